import type { ControllerModule } from '../fleet/contract';
import type { MachineKind } from '../fleet/types';
import { duetModule } from './duet/module';
import { g2coreModule } from './g2core/module';
import { pruntModule } from './prunt/module';
import { touchcutModule } from './touchcut/module';
import { xtoolModule } from './xtool/module';

/** The one registry of controller modules (browser side): kind -> module. */
export const controllers: Partial<Record<MachineKind, ControllerModule>> = {
  touchcut: touchcutModule,
  g2core: g2coreModule,
  duet: duetModule,
  xtool: xtoolModule,
  prunt: pruntModule,
};
