import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand, CommandDecl } from '../../fleet/commands';
import type { SessionContext } from '../../fleet/contract';
import { describeError } from '../../fleet/errors';
import { defineCommands } from '../../fleet/kernel';
import type { UploadTracker } from '../../fleet/upload';
import type { PruntClient } from './client';
import { PRUNT_KEYS } from './queries';
import type { ConfigState, GcodeEntry, PruntState } from './state';

/**
 * Every Prunt command, declared once with `defineCommands`. Availability reads only the stores
 * named here (the machine snapshot, the Prunt store and the config editor's store), so a button follows exactly what decides it. The ids are in the audit log and match
 * the gateway's rules (access.ts): never rename them.
 */

export interface PruntCommands {
  pause: CommandDecl<void>;
  resume: CommandDecl<void>;
  cancel: CommandDecl<void>;
  runFile: CommandDecl<string>;
  runCommand: CommandDecl<string>;
  saveConfig: CommandDecl<void>;
  reloadServer: CommandDecl<void>;
  allowFirmwareUpdate: CommandDecl<void>;
  upload: CommandDecl<{ name: string; body: Blob | string }>;
}

/** What the commands need of the session. */
export interface PruntCommandHost {
  readonly ctx: SessionContext;
  readonly client: PruntClient;
  readonly store: StoreApi<PruntState>;
  readonly config: StoreApi<ConfigState>;
  readonly uploads: UploadTracker;
  /** The config editor's save (returns the result line). */
  saveConfig(commandId: string): Promise<string>;
  /** Read the status once, now, rather than at the next tick (after a command). */
  kick(): void;
}

export function declarePruntCommands(h: PruntCommandHost): {
  cmd: PruntCommands;
  all: Readonly<Record<string, AnyCommand>>;
} {
  const cmds = defineCommands({
    snapshot: h.ctx.snapshot,
    prunt: h.store,
    config: h.config,
  });
  let gcodeSeq = 0;
  const ready = (p: PruntState): true | string =>
    p.startup === null || p.startup === 'Done' ? true : `The server is not ready (${p.startup})`;

  const pause = cmds.define({
    id: 'prunt.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: ({ snapshot }) => (snapshot.activity === 'running' ? true : 'Nothing is running'),
    perform: async (_a, c) => {
      await h.client.pause(c);
      h.kick();
      return 'pause requested';
    },
  });
  const resume = cmds.define({
    id: 'prunt.resume',
    label: 'Resume',
    hazard: 'job',
    role: 'operator',
    confirm: 'Resume? The machine starts moving again.',
    available: ({ snapshot }) => (snapshot.activity === 'paused' ? true : 'Not paused'),
    perform: async (_a, c) => {
      await h.client.resume(c);
      h.kick();
      return 'resume requested';
    },
  });
  const cancel = cmds.define({
    id: 'prunt.cancel',
    label: 'Cancel file',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Cancel the running file? It cannot be resumed.',
    available: ({ snapshot, prunt }) => {
      if (prunt.api !== 'module') return 'This server has no cancel (flat API, 2025)';
      return snapshot.activity === 'running' || snapshot.activity === 'paused' ? true : 'Nothing is running';
    },
    perform: async (_a, c) => {
      await h.client.cancel(c);
      h.kick();
      return 'cancel requested';
    },
  });
  const runFile = cmds.define<string>({
    id: 'prunt.runFile',
    label: 'Run file',
    hazard: 'job',
    role: 'operator',
    confirm: (name) => `Run ${name}? The machine will heat and move.`,
    available: ({ snapshot, prunt }) => {
      const r = ready(prunt);
      if (r !== true) return r;
      return snapshot.activity === 'running' || snapshot.activity === 'paused'
        ? 'A file is already running'
        : true;
    },
    perform: async (name, c) => {
      await h.client.runFile(name, c);
      h.kick();
      return `started ${name}`;
    },
  });
  const runCommand = cmds.define<string>({
    id: 'prunt.runCommand',
    label: 'Send G-code',
    hazard: 'motion',
    role: 'supervisor',
    confirm: false,
    perform: async (command, c) => {
      const seq = ++gcodeSeq;
      const entry: GcodeEntry = { seq, at: h.ctx.now(), command, id: null, state: 'sending', output: [] };
      h.store.setState((s) => ({ gcode: [...s.gcode, entry].slice(-200) }));
      const setEntry = (p: Partial<GcodeEntry>) =>
        h.store.setState((s) => ({ gcode: s.gcode.map((g) => (g.seq === seq ? { ...g, ...p } : g)) }));
      try {
        const id = await h.client.runCommand(command, c);
        setEntry({ id, state: id ? 'sent' : 'Completed' });
        h.kick();
        return id ? `accepted (ID ${id})` : 'accepted';
      } catch (e) {
        setEntry({ state: 'error', output: [describeError(e)] });
        throw e;
      }
    },
  });
  const saveConfig = cmds.define({
    id: 'prunt.saveConfig',
    label: 'Save configuration',
    hazard: 'adjust',
    role: 'supervisor',
    // The review dialog (every change, old → new) is the confirmation.
    confirm: false,
    available: ({ config }) => {
      if (!config.model || config.phase !== 'ready') return 'The configuration is not loaded';
      if (config.saving) return 'Saving…';
      if (config.invalid) return 'Fix the invalid values first';
      if (config.pending === 0) return 'No changes to save';
      return true;
    },
    perform: (_a, c) => h.saveConfig(c.commandId),
  });
  const reloadServer = cmds.define({
    id: 'prunt.reloadServer',
    label: 'Reload server',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm:
      'Reload the Prunt server to apply the configuration? A running file stops and the controller restarts.',
    perform: async (_a, c) => {
      await h.client.reloadServer(c);
      h.config.setState({ offerReload: false });
      return 'server reloading';
    },
  });
  const allowFirmwareUpdate = cmds.define({
    id: 'prunt.allowFirmwareUpdate',
    label: 'Allow firmware update',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm:
      'Allow the server to flash new firmware to the board? Do not switch the machine off while it runs.',
    confirmTwice: true,
    available: ({ prunt }) => (prunt.startup === 'Update_Required' ? true : 'No firmware update is required'),
    perform: async (_a, c) => {
      await h.client.allowFirmwareUpdate(c);
      h.kick();
      return 'firmware update allowed';
    },
  });
  const upload = cmds.define<{ name: string; body: Blob | string }>({
    id: 'prunt.upload',
    label: 'Upload file',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    // The file list refetches after a successful upload.
    invalidates: [PRUNT_KEYS.files],
    perform: async ({ name, body }, c) => {
      const total = typeof body === 'string' ? body.length : body.size;
      await h.uploads.run(
        { name, total },
        (u) =>
          h.client.upload(name, body, { commandId: c.commandId, onProgress: u.progress, signal: u.signal }),
        { message: () => null },
      );
      return `uploaded ${name}`;
    },
  });
  return {
    cmd: {
      pause,
      resume,
      cancel,
      runFile,
      runCommand,
      saveConfig,
      reloadServer,
      allowFirmwareUpdate,
      upload,
    },
    all: cmds.all,
  };
}
