import type { StoreApi } from 'zustand/vanilla';
import { defineCommands, type RunToken } from '../../fleet/kernel';
import type { MachineSnapshot } from '../../fleet/types';
import type { TouchcutClient } from './client';
import type { TouchcutState } from './state';

/**
 * What a TouchCut session commands. The REST API is read-only for the machine: the only command
 * is the TouchCut user's own password change (`POST rest/v1/auth/change-password`), which needs a
 * user login (the JWT the gateway holds), never the API key (manual, "Managing REST API Keys").
 */

export interface ChangePasswordArgs {
  oldPassword: string;
  newPassword: string;
  confirmPassword: string;
}

export function touchcutCommands(
  stores: { snapshot: StoreApi<MachineSnapshot>; touchcut: StoreApi<TouchcutState> },
  client: TouchcutClient,
  /** The session's current run: an answer is written only while the run that sent it lasts. */
  run: () => RunToken,
) {
  const cmds = defineCommands(stores);
  const changePassword = cmds.define<ChangePasswordArgs>({
    id: 'touchcut.changePassword',
    label: 'Change TouchCut password',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    available: ({ touchcut }) =>
      touchcut.auth.mode === 'user'
        ? true
        : 'Needs a TouchCut user login (an API key cannot change a password)',
    perform: async (args, c) => {
      const sent = run();
      // The gateway keeps the new JWT; the answer says until when the login now lasts.
      const held = await client.changePassword(args, c.commandId);
      if (sent.alive())
        stores.touchcut.setState((s) => ({ auth: { ...s.auth, expiresAt: held.expiresAt ?? null } }));
      return 'password changed; the console now uses the new login';
    },
  });
  return { all: cmds.all, changePassword };
}
