import type { ControllerModule } from '../fleet/contract';
import type { MachineKind } from '../fleet/types';
import { xtoolModule } from './xtool/module';

/** The one registry of controller modules (browser side): kind -> module. */
export const controllers: Partial<Record<MachineKind, ControllerModule>> = {
  xtool: xtoolModule,
};
