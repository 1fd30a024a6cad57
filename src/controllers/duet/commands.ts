import type { StoreApi } from 'zustand/vanilla';
import type { SessionContext } from '../../fleet/contract';
import { defineCommands } from '../../fleet/kernel';
import type { MachineSnapshot } from '../../fleet/types';
import { JOBS_DIR } from './access';
import { baseName, joinPath, quoteGcode, type DuetClient } from './client';
import { READ } from './reads';
import { isPrinting } from './snapshot';
import type { CodeArgs, DuetState } from './state';
import type { MessageBox } from './wire';

/**
 * Every Duet command, declared once with `defineCommands`. Availability reads only the two
 * stores named here (the machine snapshot and the Duet store), so a button shows exactly what
 * the runner would do. The ids are in the audit log and in the gateway's access rules
 * (`access.ts`): never rename one.
 */

/** What the commands need from the session (its requests, with its 401/403 rules). */
export interface CommandHost {
  ctx: SessionContext;
  store: StoreApi<DuetState>;
  client: DuetClient;
  /** A command request: sent once, never resent after a 403; the machine is read again after it. */
  send<T>(fn: () => Promise<T>): Promise<T>;
  /** A command went through without `send` (emergency stop): read the machine again now. */
  sent(): void;
  upload(file: Blob, path: string, commandId: string): Promise<string>;
  /** Files changed: their info is stale (null: anything under a folder). */
  filesChanged(paths: readonly string[] | null): void;
}

export type FileArgs = { file: Blob; name: string; dir: string };

/** Listings change with files; the height map with G29 (console, macros) and file operations. */
const FILES = [[READ.dir], [READ.heightMap]] as const;
const HEIGHT_MAP = [[READ.heightMap]] as const;

/** A reply of `POST /machine/code`, line by line, into the console log. */
function logReply(h: CommandHost, reply: string): void {
  const t = reply.trim();
  if (!t) return;
  for (const line of t.split('\n')) {
    const level = line.startsWith('Error:') ? 'error' : line.startsWith('Warning:') ? 'warning' : 'info';
    h.ctx.log.add(level, 'console', line);
  }
}

/** Send G-code; the reply goes to the console log. An "Error:" reply fails the command. */
async function sendCode(h: CommandHost, code: string, commandId: string): Promise<string> {
  h.ctx.log.add('info', 'console', `> ${code.replace(/\n/g, ' | ')}`);
  const reply = await h.send(() => h.client.code(code, { commandId }));
  logReply(h, reply);
  const err = reply
    .split('\n')
    .map((l) => l.trim())
    .find((l) => l.startsWith('Error:'));
  if (err) throw new Error(err);
  return reply.trim() || 'ok';
}

export function declareCommands(h: CommandHost) {
  const cmds = defineCommands({ snapshot: h.ctx.snapshot, duet: h.store });
  const code = (gcode: string, commandId: string) => sendCode(h, gcode, commandId);
  const status = (d: DuetState) => d.model?.state.status;
  const printing = (d: DuetState) => (d.model ? isPrinting(d.model.state.status) : false);
  const idle = ({ snapshot, duet }: { snapshot: MachineSnapshot; duet: DuetState }) =>
    snapshot.activity === 'idle' && !printing(duet) ? true : 'The machine is not idle';

  const start = cmds.define<{ path: string }>({
    id: 'duet.start',
    label: 'Start print',
    hazard: 'job',
    role: 'operator',
    confirm: (a) =>
      `Start printing ${baseName(a.path)}? The heaters will switch on and the machine will move.`,
    available: idle,
    perform: (a, c) => code(`M32 ${quoteGcode(a.path)}`, c.commandId),
  });
  const simulate = cmds.define<{ path: string }>({
    id: 'duet.simulate',
    label: 'Simulate',
    hazard: 'job',
    role: 'operator',
    confirm: (a) =>
      `Simulate ${baseName(a.path)}? Nothing moves; the machine is busy until the simulation ends.`,
    available: idle,
    perform: (a, c) => code(`M37 P${quoteGcode(a.path)}`, c.commandId),
  });
  const pause = cmds.define({
    id: 'duet.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: ({ duet }) => {
      const st = status(duet);
      return st === 'processing' || st === 'simulating' ? true : 'Nothing is printing';
    },
    perform: (_a, c) => code('M25', c.commandId),
  });
  const resume = cmds.define({
    id: 'duet.resume',
    label: 'Resume',
    hazard: 'job',
    role: 'operator',
    confirm: 'Resume the print? The machine will move.',
    available: ({ duet }) => (status(duet) === 'paused' ? true : 'Only a paused print can be resumed'),
    perform: (_a, c) => code('M24', c.commandId),
  });
  // Cancel only while paused, as Duet Web Control offers it.
  const cancel = cmds.define({
    id: 'duet.cancel',
    label: 'Cancel print',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Cancel the print? It cannot be resumed afterwards.',
    available: ({ duet }) =>
      status(duet) === 'paused' ? true : 'Pause the print first: only a paused print can be cancelled',
    perform: (_a, c) => code('M0', c.commandId),
  });
  // One tap, no confirmation: M112 then M999 (reset) in one request.
  const estop = cmds.define({
    id: 'duet.estop',
    label: 'Emergency stop',
    hazard: 'stop',
    role: 'operator',
    confirm: false,
    perform: async (_a, c) => {
      h.ctx.log.add('warning', 'console', '> M112 | M999 (emergency stop)');
      const reply = await h.client.code('M112\nM999', { commandId: c.commandId, timeoutMs: 10_000 });
      h.sent();
      logReply(h, reply);
      return 'emergency stop sent';
    },
  });
  const console = cmds.define<CodeArgs>({
    id: 'duet.code',
    label: 'Send G-code',
    hazard: 'motion',
    role: 'supervisor',
    confirm: false,
    invalidates: HEIGHT_MAP,
    perform: async (a, c) => {
      h.store.setState((s) => ({
        codeHistory: [...s.codeHistory.filter((x) => x !== a.code), a.code].slice(-100),
      }));
      h.ctx.log.add('info', 'console', `> ${a.code.replace(/\n/g, ' | ')}`);
      const reply = await h.send(() => h.client.code(a.code, { commandId: c.commandId, async: a.async }));
      logReply(h, reply);
      return reply.trim() || (a.async ? 'sent (async)' : 'ok');
    },
  });
  const answer = cmds.define<{ box: MessageBox; cancel?: boolean; value?: number | string }>({
    id: 'duet.messageBox',
    label: 'Answer message',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    perform: (a, c) => code(messageBoxReply(a.box, a.cancel ?? false, a.value), c.commandId),
  });
  const heaterReset = cmds.define<{ heater: number }>({
    id: 'duet.heaterReset',
    label: 'Reset heater fault',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm: (a) =>
      `Reset the fault of heater ${a.heater}? Find out why it faulted first: the heater can be switched on again afterwards.`,
    perform: (a, c) => code(`M562 P${a.heater}`, c.commandId),
  });
  const macro = cmds.define<{ path: string }>({
    id: 'duet.macro',
    label: 'Run macro',
    hazard: 'motion',
    role: 'supervisor',
    confirm: (a) => `Run the macro ${baseName(a.path)}? It may move the machine or switch heaters on.`,
    available: ({ duet }) => (printing(duet) ? 'A job is running' : true),
    invalidates: HEIGHT_MAP,
    perform: (a, c) => code(`M98 P${quoteGcode(a.path)}`, c.commandId),
  });
  const uploadJob = cmds.define<FileArgs>({
    id: 'duet.uploadJob',
    label: 'Upload job file',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    invalidates: FILES,
    perform: (a, c) => h.upload(a.file, joinPath(a.dir, a.name), c.commandId),
  });
  const upload = cmds.define<FileArgs>({
    id: 'duet.upload',
    label: 'Upload file',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: false,
    invalidates: FILES,
    perform: (a, c) => h.upload(a.file, joinPath(a.dir, a.name), c.commandId),
  });
  const del = cmds.define<{ path: string; dir: boolean }>({
    id: 'duet.delete',
    label: 'Delete',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: (a) => (a.dir ? `Delete the folder ${a.path} and everything in it?` : `Delete ${a.path}?`),
    invalidates: FILES,
    perform: async (a, c) => {
      await h.send(() => h.client.deleteFile(a.path, { recursive: a.dir, commandId: c.commandId }));
      h.filesChanged(a.dir ? null : [a.path]);
      return `deleted ${a.path}`;
    },
  });
  const move = cmds.define<{ from: string; to: string; force?: boolean }>({
    id: 'duet.move',
    label: 'Rename / move',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: false,
    invalidates: FILES,
    perform: async (a, c) => {
      await h.send(() => h.client.move(a.from, a.to, { force: a.force, commandId: c.commandId }));
      // A folder may have moved: then anything under it changed its path.
      h.filesChanged(null);
      return `moved to ${a.to}`;
    },
  });
  const mkdir = cmds.define<{ path: string }>({
    id: 'duet.mkdir',
    label: 'New folder',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: false,
    invalidates: FILES,
    perform: async (a, c) => {
      await h.send(() => h.client.makeDirectory(a.path, c.commandId));
      return `created ${a.path}`;
    },
  });
  const pluginInstall = cmds.define<{ file: Blob; name: string }>({
    id: 'duet.pluginInstall',
    label: 'Install plugin',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm: (a) => `Install the plugin ${a.name}? Plugins run code on the machine's computer.`,
    perform: async (a, c) => {
      await h.send(() => h.client.installPlugin(a.file, c.commandId));
      return `installed ${a.name}`;
    },
  });
  const pluginUninstall = cmds.define<{ id: string }>({
    id: 'duet.pluginUninstall',
    label: 'Uninstall plugin',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm: (a) => `Uninstall the plugin ${a.id}?`,
    perform: async (a, c) => {
      await h.send(() => h.client.uninstallPlugin(a.id, c.commandId));
      return `uninstalled ${a.id}`;
    },
  });
  const pluginStart = cmds.define<{ id: string }>({
    id: 'duet.pluginStart',
    label: 'Start plugin',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: false,
    perform: async (a, c) => {
      await h.send(() => h.client.startPlugin(a.id, c.commandId));
      return `started ${a.id}`;
    },
  });
  const pluginStop = cmds.define<{ id: string }>({
    id: 'duet.pluginStop',
    label: 'Stop plugin',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: (a) => `Stop the plugin ${a.id}?`,
    perform: async (a, c) => {
      await h.send(() => h.client.stopPlugin(a.id, c.commandId));
      return `stopped ${a.id}`;
    },
  });
  const cmd = {
    start,
    simulate,
    pause,
    resume,
    cancel,
    estop,
    console,
    answer,
    heaterReset,
    macro,
    uploadJob,
    upload,
    del,
    move,
    mkdir,
    pluginInstall,
    pluginUninstall,
    pluginStart,
    pluginStop,
  };
  return { cmd, all: cmds.all };
}

export type DuetCommands = ReturnType<typeof declareCommands>['cmd'];

/** Which upload command applies to a directory (operator only into the jobs folder). */
export function uploadCommandFor(cmd: DuetCommands, dir: string): DuetCommands['upload'] {
  const d = dir.endsWith('/') ? dir : `${dir}/`;
  return d.startsWith(JOBS_DIR) ? cmd.uploadJob : cmd.upload;
}

/**
 * The M292 answer the firmware expects: `P1` cancels, `S<seq>` names the box, `R{…}` carries the
 * value (choice index for mode 4, a number for 5/6, a quoted string for 7).
 */
export function messageBoxReply(box: MessageBox, cancel: boolean, value?: number | string): string {
  if (cancel) return `M292 P1 S${box.seq}`;
  let r = '';
  if (value !== undefined && box.mode >= 4) {
    r =
      typeof value === 'string' && box.mode === 7
        ? ` R{"${value.replace(/"/g, '""')}"}`
        : ` R{${Number(value)}}`;
  }
  return `M292 P0 S${box.seq}${r}`;
}

/** Keep a value inside the box's limits (integer/float/string length). Returns an error text or null. */
export function validateBoxValue(
  box: MessageBox,
  raw: string,
): { value: number | string } | { error: string } {
  if (box.mode === 7) {
    if (box.min !== null && raw.length < box.min) return { error: `At least ${box.min} characters` };
    if (box.max !== null && raw.length > box.max) return { error: `At most ${box.max} characters` };
    return { value: raw };
  }
  const n = Number(raw);
  if (raw.trim() === '' || Number.isNaN(n)) return { error: 'Enter a number' };
  if (box.mode === 5 && !Number.isInteger(n)) return { error: 'Enter a whole number' };
  if (box.min !== null && n < box.min) return { error: `At least ${box.min}` };
  if (box.max !== null && n > box.max) return { error: `At most ${box.max}` };
  return { value: n };
}
