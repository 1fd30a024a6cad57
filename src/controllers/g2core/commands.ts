import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand, CommandDecl } from '../../fleet/commands';
import type { SessionContext } from '../../fleet/contract';
import { defineCommands, type RunToken } from '../../fleet/kernel';
import type { MachineSnapshot } from '../../fleet/types';
import { STAT_ALARM, STAT_HOLD, STAT_PANIC, STAT_SHUTDOWN, STUCK_IN_RUN, statLabel } from './codes';
import type { G2coreClient } from './client';
import {
  IDLE,
  MOVING,
  activeJog,
  activeTarget,
  formatPercent,
  jogLines,
  runningJob,
  statOf,
  type AxisLetter,
  type G2Detail,
  type JogArgs,
  type SettingArgs,
} from './model';
import type { OpTracker } from './operations';
import { JOBS_KEY, SETTINGS_GROUP_KEY } from './queries';

/**
 * Every g2core command, declared once with `defineCommands`. Availability reads only the
 * machine snapshot and the family's `detail` store (so every button of a command follows
 * exactly those). The ids are in the audit log and match the gateway's rules (access.ts):
 * never rename one.
 */

/** What the commands need of the session (the session implements it). */
export interface CommandHost {
  readonly ctx: SessionContext;
  readonly client: G2coreClient;
  readonly detail: StoreApi<G2Detail>;
  /** The command work on operations (operations.ts). */
  readonly ops: Pick<OpTracker, 'start' | 'control' | 'kill' | 'sendMdi' | 'clearAlarm'>;
  /** Poll again right after any poll in flight; `jobs`: read the job list in that poll too. */
  refresh(jobs?: boolean): void;
  /** The current run: an answer is written only while the run that sent the command is current. */
  run(): RunToken;
  writeSetting(a: SettingArgs, commandId: string): Promise<string>;
}

export interface G2Commands {
  feedhold: CommandDecl<void>;
  resume: CommandDecl<void>;
  kill: CommandDecl<void>;
  stopJog: CommandDecl<void>;
  clearAlarm: CommandDecl<void>;
  resetBoard: CommandDecl<void>;
  home: CommandDecl<{ axes: AxisLetter[] }>;
  jog: CommandDecl<JogArgs>;
  mdi: CommandDecl<{ text: string }>;
  queueJob: CommandDecl<{ name: string; gcode: string } | { name: string; file: Blob }>;
  runJob: CommandDecl<{ id: string; name: string }>;
  removeJob: CommandDecl<{ id: string }>;
  moveJob: CommandDecl<{ id: string; position: number }>;
  setSetting: CommandDecl<SettingArgs>;
  setOverride: CommandDecl<{ key: 'mfo' | 'sso'; value: number }>;
  all: Readonly<Record<string, AnyCommand>>;
}

type States = { snapshot: MachineSnapshot; g2: G2Detail };

const idle = ({ snapshot, g2 }: States): true | string => {
  const st = statOf(snapshot, g2);
  if (st === null) return 'No status yet';
  return IDLE.has(st) ? true : `Only while idle (the machine is in ${statLabel(st)})`;
};

/** Something of this console (or found with GET /operation) moves: holds and kills act on it. */
const inMotion = (g2: G2Detail): true | string => {
  if (activeTarget(g2)) return true;
  return g2.opsList
    ? 'Looking for the operation that moves the machine…'
    : 'Started elsewhere and this controller cannot list its operations: hold it where it was started or at the machine';
};

const moving = ({ snapshot, g2 }: States): true | string => {
  const st = statOf(snapshot, g2);
  if (st === null || !MOVING.has(st)) return 'Nothing is moving';
  return inMotion(g2);
};

/** The gateway's serial bridge says the board is stuck in run (its status reads answer so). */
export function isStuckInRun(snapshot: MachineSnapshot): boolean {
  return snapshot.problem?.message.includes(STUCK_IN_RUN) ?? false;
}

/** The job list changes with these: the Jobs tab (and the next slow poll) reads it again. */
const JOBS = [JOBS_KEY];

export function declareCommands(host: CommandHost): G2Commands {
  const cmds = defineCommands({ snapshot: host.ctx.snapshot, g2: host.detail });
  const { client } = host;

  const feedhold = cmds.define({
    id: 'g2core.feedhold',
    label: 'Feedhold',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: ({ snapshot, g2 }) => {
      const st = statOf(snapshot, g2);
      if (st === null || ![5, 7, 8, 9, 10].includes(st)) return 'Nothing is moving';
      return inMotion(g2);
    },
    invalidates: JOBS,
    perform: (_a, c) => host.ops.control('pause', c.commandId),
  });
  const resume = cmds.define({
    id: 'g2core.resume',
    label: 'Cycle start',
    hazard: 'job',
    role: 'operator',
    confirm: 'Cycle start: resume motion from the hold?',
    available: ({ snapshot, g2 }) => (statOf(snapshot, g2) === STAT_HOLD ? inMotion(g2) : 'Only in feedhold'),
    invalidates: JOBS,
    perform: (_a, c) => host.ops.control('run', c.commandId),
  });
  const kill = cmds.define({
    id: 'g2core.kill',
    label: 'Kill',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Kill: stop motion now, flush the queue and abandon the job? It cannot be resumed.',
    available: ({ snapshot, g2 }) => {
      const st = statOf(snapshot, g2);
      return st === null || !MOVING.has(st) ? 'Nothing is running' : inMotion(g2);
    },
    invalidates: JOBS,
    perform: (_a, c) => host.ops.control('kill', c.commandId),
  });
  const stopJog = cmds.define({
    id: 'g2core.stop-jog',
    label: 'STOP',
    hazard: 'stop',
    role: 'operator',
    confirm: false,
    // The big STOP stops whatever moves: the jog or homing first, else the job or operation
    // in motion (a STOP that stays grey while the machine moves would be worse than none).
    available: (s) => (activeJog(s.g2) ? true : moving(s)),
    invalidates: JOBS,
    perform: (_a, c) => {
      const op = activeJog(host.detail.getState());
      return op ? host.ops.kill(op, c.commandId) : host.ops.control('kill', c.commandId);
    },
  });
  const clearAlarm = cmds.define({
    id: 'g2core.clear-alarm',
    label: 'Clear alarm',
    hazard: 'adjust',
    role: 'operator',
    confirm:
      'Clear the alarm? Check that the cause (limit switch, crash, shutdown input) has been dealt with.',
    available: ({ snapshot, g2 }) => {
      const st = statOf(snapshot, g2);
      if (st === STAT_PANIC) return 'PANIC needs a reset or power cycle of the controller';
      return st === STAT_ALARM || st === STAT_SHUTDOWN ? true : 'No alarm to clear';
    },
    perform: async (_a, c) => {
      await host.ops.clearAlarm(c.commandId);
      return 'alarm cleared';
    },
  });
  const resetBoard = cmds.define({
    id: 'g2core.reset-board',
    label: 'Reset the board',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm:
      'Reset the board (^X)? The job is abandoned where it stands and the board restarts: check the machine, then home it before running again.',
    // Its reads fail while the board is stuck (the link is "reconnecting"): it goes all the same.
    whileInDoubt: true,
    available: ({ snapshot }) =>
      isStuckInRun(snapshot) ? true : 'Only for a board the gateway reports stuck in run',
    invalidates: JOBS,
    perform: async (_a, c) => {
      await client.resetBoard(c.commandId);
      host.refresh(true);
      return 'reset sent to the board';
    },
  });
  const home = cmds.define<{ axes: AxisLetter[] }>({
    id: 'g2core.home',
    label: 'Home',
    hazard: 'motion',
    role: 'operator',
    confirm: (a) =>
      `Home ${a.axes.map((x) => x.toUpperCase()).join(' ')}? The machine moves to its home switches.`,
    available: idle,
    perform: async (a, c) => {
      const line = `G28.2 ${a.axes.map((x) => `${x.toUpperCase()}0`).join(' ')}`;
      const id = await host.ops.start('home', `Home ${a.axes.join(' ').toUpperCase()}`, [line], c.commandId);
      return `homing started (operation ${id})`;
    },
  });
  const jog = cmds.define<JogArgs>({
    id: 'g2core.jog',
    label: 'Jog',
    hazard: 'motion',
    role: 'operator',
    confirm: false,
    available: idle,
    perform: async (a, c) => {
      const label = `Jog ${a.axis.toUpperCase()}${a.distance >= 0 ? '+' : ''}${a.distance}`;
      await host.ops.start('jog', label, jogLines(a), c.commandId);
      return label;
    },
  });
  const mdi = cmds.define<{ text: string }>({
    id: 'g2core.mdi',
    label: 'Send G-code',
    hazard: 'motion',
    role: 'supervisor',
    confirm: false,
    available: ({ snapshot, g2 }) => {
      const st = statOf(snapshot, g2);
      if (st === null) return 'No status yet';
      if (st === STAT_ALARM || st === STAT_SHUTDOWN || st === STAT_PANIC) return 'Clear the alarm first';
      // Lines sent now would wait behind the motion in progress and run later, maybe unattended:
      // only while idle, or behind this console's own MDI lines (a sequence typed on purpose).
      const job = runningJob(g2.jobs);
      if (job) return `Not while job "${job.name ?? job.id}" runs: the lines would wait until it ends`;
      if (IDLE.has(st)) return true;
      const t = activeTarget(g2);
      if (t?.kind === 'op' && g2.ops[t.id]?.purpose === 'mdi') return true;
      return `Only while idle (the machine is in ${statLabel(st)}): the lines would wait behind the motion`;
    },
    perform: (a, c) => host.ops.sendMdi(a.text, c.commandId),
  });
  const queueJob = cmds.define<{ name: string; gcode: string } | { name: string; file: Blob }>({
    id: 'g2core.queue-job',
    label: 'Queue job',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    invalidates: JOBS,
    perform: async (a, c) => {
      const run = host.run();
      const id = await client.createJob(a, c.commandId);
      if (run.alive())
        host.detail.setState({ notice: `"${a.name}" queued as job ${id}. Start it from the queue.` });
      host.refresh(true);
      return `job ${id} queued`;
    },
  });
  const runJob = cmds.define<{ id: string; name: string }>({
    id: 'g2core.run-job',
    label: 'Start job',
    hazard: 'job',
    role: 'operator',
    confirm: (a) =>
      `Start job "${a.name}"? The machine will move. Check the stock, the tool and the work zero.`,
    available: idle,
    invalidates: JOBS,
    perform: async (a, c) => {
      await client.controlJob(a.id, { state: 'run' }, c.commandId);
      host.refresh(true);
      return `job ${a.id} started`;
    },
  });
  const removeJob = cmds.define<{ id: string }>({
    id: 'g2core.remove-job',
    label: 'Remove from queue',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    invalidates: JOBS,
    perform: async (a, c) => {
      await client.controlJob(a.id, { state: 'kill' }, c.commandId);
      host.refresh(true);
      return `job ${a.id} removed from the queue`;
    },
  });
  const moveJob = cmds.define<{ id: string; position: number }>({
    id: 'g2core.move-job',
    label: 'Move in queue',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    invalidates: JOBS,
    perform: async (a, c) => {
      await client.controlJob(a.id, { position: a.position }, c.commandId);
      host.refresh(true);
      return `job ${a.id} moved to position ${a.position + 1}`;
    },
  });
  const setSetting = cmds.define<SettingArgs>({
    id: 'g2core.set-setting',
    label: 'Change setting',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: false,
    // The group on screen reads the value the controller now holds.
    invalidates: [SETTINGS_GROUP_KEY],
    perform: (a, c) => host.writeSetting(a, c.commandId),
  });
  const setOverride = cmds.define<{ key: 'mfo' | 'sso'; value: number }>({
    id: 'g2core.override',
    label: 'Override',
    hazard: 'adjust',
    role: 'operator',
    confirm: false,
    perform: async (a, c) => {
      const v = await client.setKey(null, a.key, a.value, c.commandId);
      host.refresh();
      return `${a.key === 'mfo' ? 'feed' : 'spindle'} override ${formatPercent(v)}`;
    },
  });

  return {
    feedhold,
    resume,
    kill,
    stopJog,
    clearAlarm,
    resetBoard,
    home,
    jog,
    mdi,
    queueJob,
    runJob,
    removeJob,
    moveJob,
    setSetting,
    setOverride,
    all: cmds.all,
  };
}
