import { createStore, type StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../../fleet/contract';
import { LinkError, describeError } from '../../fleet/errors';
import { Poller } from '../../fleet/link';
import type { Activity, Alarm, JobSummary, MachineInfo, MachineSnapshot } from '../../fleet/types';
import {
  STAT_ALARM,
  STAT_HOLD,
  STAT_INTERLOCK,
  STAT_PANIC,
  STAT_SHUTDOWN,
  statLabel,
  statusText,
} from './codes';
import { G2coreClient, g2StatusOf, type OpControl } from './client';
import type { Job, Operation, Scalar, SettingsGroup, SrValues, VersionInfo } from './wire';

/** Status reports about 4 per second while the page is visible (the Poller slows down when hidden). */
export const SR_POLL_MS = 250;
/** Job list and tracked operations: every Nth status poll (about once a second). */
const SLOW_EVERY = 4;
/** A full (unfiltered) status report now and then, in case a changed-only answer was lost. */
const FULL_EVERY = 40;

export const AXIS_LETTERS = ['x', 'y', 'z', 'a', 'b', 'c'] as const;
export type AxisLetter = (typeof AXIS_LETTERS)[number];

/** The states in which the machine moves (or holds in the middle of a move). */
const MOVING = new Set([5, 6, 7, 8, 9, 10, 11]);
/** Idle states: commands that start motion are available. */
const IDLE = new Set([1, 3, 4]);

export interface TrackedOp {
  id: string;
  /** What the console started it for ("jog X+10", "MDI", "home"). */
  purpose: 'jog' | 'home' | 'mdi' | 'clear' | 'other';
  label: string;
  lines: string[];
  op: Operation | null;
  startedAt: number;
}

export interface ConsoleEntry {
  seq: number;
  at: number;
  lines: string[];
  opId: string | null;
  state: 'sent' | 'running' | 'done' | 'error' | 'refused';
  /** Status text on error ("Gcode command unsupported — G999 (status 131)"). */
  message: string | null;
}

export interface G2Detail {
  version: VersionInfo | null;
  /** Merged status values (from filtered reports). */
  sr: SrValues;
  /** Axes whose mode (am) is not 0; x, y, z until known. */
  axes: AxisLetter[];
  overrides: { mfoe: boolean | null; ssoe: boolean | null };
  jobs: Job[];
  jobsError: string | null;
  ops: Record<string, TrackedOp>;
  console: ConsoleEntry[];
  /** A sentence for the operator after a command ("Job queued"). */
  notice: string | null;
}

export interface SettingsState {
  groups: string[] | null;
  groupsError: string | null;
  values: Record<string, SettingsGroup>;
  loading: Record<string, boolean>;
  errors: Record<string, string>;
  /** Per field "group.key": the refusal text of the last attempt. */
  fieldErrors: Record<string, string>;
  /** Keys the controller refused as read-only (status 104) — shown as such from then on. */
  refusedReadOnly: Record<string, true>;
  saved: Record<string, number>;
}

export function initialDetail(): G2Detail {
  return {
    version: null,
    sr: {},
    axes: ['x', 'y', 'z'],
    overrides: { mfoe: null, ssoe: null },
    jobs: [],
    jobsError: null,
    ops: {},
    console: [],
    notice: null,
  };
}

const num = (v: Scalar | undefined): number | null =>
  typeof v === 'number' && Number.isFinite(v) ? v : null;

/** stat → normalized activity (stat is the only state a UI should rely on: state-enums.json). */
export function activityOf(stat: number | null): Activity {
  switch (stat) {
    case 1:
    case 3:
    case 4:
      return 'idle';
    case 2:
    case 12:
    case 13:
      return 'alarm';
    case 5:
    case 7:
    case 8:
    case 9:
    case 10:
      return 'running';
    case 6:
    case 11:
      return 'paused';
    default:
      return 'unknown';
  }
}

/** What each stopping state means and what clears it (firmware table: 204/205 "$clear", 206 "^x"). */
export function alarmsOf(stat: number | null, since: number, lastError: string | null): Alarm[] {
  const why = lastError ? ` Last error: ${lastError}.` : '';
  if (stat === STAT_ALARM) {
    return [
      {
        id: 'g2core-alarm',
        severity: 'critical',
        message: `ALARM: the machine stopped (limit switch, soft limit or an alarm command) and rejects commands.${why}`,
        since,
        clears: 'Clear alarm (after checking the machine); position may be lost — home again',
      },
    ];
  }
  if (stat === STAT_SHUTDOWN) {
    return [
      {
        id: 'g2core-shutdown',
        severity: 'critical',
        message: `SHUTDOWN: an external shutdown (e-stop input) stopped the machine.${why}`,
        since,
        clears: 'Release the shutdown input, then Clear alarm; or reset the controller',
      },
    ];
  }
  if (stat === STAT_PANIC) {
    return [
      {
        id: 'g2core-panic',
        severity: 'critical',
        message: `PANIC: the controller detected an internal fault and will not process commands.${why}`,
        since,
        clears: 'Reset (^X / reset button) or power cycle the controller — Clear alarm does not work',
      },
    ];
  }
  if (stat === STAT_INTERLOCK) {
    return [
      {
        id: 'g2core-interlock',
        severity: 'warning',
        message: 'Safety interlock is open: motion is held.',
        since,
        clears: 'Close the interlock, then Cycle start',
      },
    ];
  }
  return [];
}

export interface JogArgs {
  axis: AxisLetter;
  distance: number;
  feed: number;
}

export interface SettingArgs {
  group: string;
  key: string;
  value: unknown;
}

export class G2coreSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly client: G2coreClient;
  readonly detail: StoreApi<G2Detail> = createStore<G2Detail>(() => initialDetail());
  readonly settings: StoreApi<SettingsState> = createStore<SettingsState>(() => ({
    groups: null,
    groupsError: null,
    values: {},
    loading: {},
    errors: {},
    fieldErrors: {},
    refusedReadOnly: {},
    saved: {},
  }));
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  private readonly tracker: LinkTracker;
  private readonly poller: Poller;
  private polls = 0;
  private infoLoaded = false;
  private lastError: string | null = null;
  private alarmSince: { stat: number; at: number } | null = null;
  private consoleSeq = 0;

  readonly feedhold: CommandDecl<void>;
  readonly resume: CommandDecl<void>;
  readonly kill: CommandDecl<void>;
  readonly stopJog: CommandDecl<void>;
  readonly clearAlarm: CommandDecl<void>;
  readonly home: CommandDecl<{ axes: AxisLetter[] }>;
  readonly jog: CommandDecl<JogArgs>;
  readonly mdi: CommandDecl<{ text: string }>;
  readonly queueJob: CommandDecl<{ name: string; gcode: string } | { name: string; file: Blob }>;
  readonly runJob: CommandDecl<{ id: string; name: string }>;
  readonly removeJob: CommandDecl<{ id: string }>;
  readonly moveJob: CommandDecl<{ id: string; position: number }>;
  readonly setSetting: CommandDecl<SettingArgs>;
  readonly setOverride: CommandDecl<{ key: 'mfo' | 'sso'; value: number }>;

  constructor(readonly ctx: SessionContext) {
    this.machine = ctx.machine;
    this.client = new G2coreClient(ctx.machine.id);
    this.tracker = new LinkTracker(ctx);
    this.poller = new Poller({
      run: () => this.poll(),
      intervalMs: () => SR_POLL_MS,
      visibility: ctx.visibility,
      onError: (e) => this.onPollError(e),
      retryDelayMs: () => this.retryDelay,
    });

    const stat = (s: MachineSnapshot) => (s.link === 'online' ? this.stat() : null);
    const idle = (s: MachineSnapshot): true | string => {
      const st = stat(s);
      if (st === null) return 'No status yet';
      return IDLE.has(st) ? true : `Only while idle (the machine is in ${statLabel(st)})`;
    };
    const inMotion = (): true | string => {
      if (this.activeTarget()) return true;
      return this.opsListSupported
        ? 'Looking for the operation that moves the machine…'
        : 'Started elsewhere and this controller cannot list its operations: hold it where it was started or at the machine';
    };

    this.feedhold = {
      id: 'g2core.feedhold',
      label: 'Feedhold',
      hazard: 'job',
      role: 'operator',
      confirm: false,
      available: (s) => {
        const st = stat(s);
        if (st === null || ![5, 7, 8, 9, 10].includes(st)) return 'Nothing is moving';
        return inMotion();
      },
      perform: (_a, c) => this.controlActive('pause', c.commandId),
    };
    this.resume = {
      id: 'g2core.resume',
      label: 'Cycle start',
      hazard: 'job',
      role: 'operator',
      confirm: 'Cycle start: resume motion from the hold?',
      available: (s) => (stat(s) === STAT_HOLD ? inMotion() : 'Only in feedhold'),
      perform: (_a, c) => this.controlActive('run', c.commandId),
    };
    this.kill = {
      id: 'g2core.kill',
      label: 'Kill',
      hazard: 'stop',
      role: 'operator',
      confirm: 'Kill: stop motion now, flush the queue and abandon the job? It cannot be resumed.',
      available: (s) => {
        const st = stat(s);
        if (st === null || !MOVING.has(st)) return 'Nothing is running';
        return inMotion();
      },
      perform: (_a, c) => this.controlActive('kill', c.commandId),
    };
    this.stopJog = {
      id: 'g2core.stop-jog',
      label: 'STOP',
      hazard: 'stop',
      role: 'operator',
      confirm: false,
      // The big STOP stops whatever moves: the jog or homing first, else the job or operation
      // in motion (a STOP that stays grey while the machine moves would be worse than none).
      available: (s) => {
        if (this.activeJog()) return true;
        const st = stat(s);
        if (st === null || !MOVING.has(st)) return 'Nothing is moving';
        return inMotion();
      },
      perform: async (_a, c) => {
        const op = this.activeJog();
        if (!op) return this.controlActive('kill', c.commandId);
        await this.client.controlOperation(op.id, 'kill', c.commandId);
        this.poller.kick();
        return `${op.label} stopped`;
      },
    };
    this.clearAlarm = {
      id: 'g2core.clear-alarm',
      label: 'Clear alarm',
      hazard: 'adjust',
      role: 'operator',
      confirm:
        'Clear the alarm? Check that the cause (limit switch, crash, shutdown input) has been dealt with.',
      available: (s) => {
        const st = stat(s);
        if (st === STAT_PANIC) return 'PANIC needs a reset or power cycle of the controller';
        return st === STAT_ALARM || st === STAT_SHUTDOWN ? true : 'No alarm to clear';
      },
      perform: async (_a, c) => {
        await this.client.clearAlarm(c.commandId);
        this.lastError = null;
        this.poller.kick();
        return 'alarm cleared';
      },
    };
    this.home = {
      id: 'g2core.home',
      label: 'Home',
      hazard: 'motion',
      role: 'operator',
      confirm: (a) =>
        `Home ${a.axes.map((x) => x.toUpperCase()).join(' ')}? The machine moves to its home switches.`,
      available: idle,
      perform: async (a, c) => {
        const line = `G28.2 ${a.axes.map((x) => `${x.toUpperCase()}0`).join(' ')}`;
        const id = await this.startOp('home', `Home ${a.axes.join(' ').toUpperCase()}`, [line], c.commandId);
        return `homing started (operation ${id})`;
      },
    };
    this.jog = {
      id: 'g2core.jog',
      label: 'Jog',
      hazard: 'motion',
      role: 'operator',
      confirm: false,
      available: idle,
      perform: async (a, c) => {
        const lines = jogLines(a);
        const label = `Jog ${a.axis.toUpperCase()}${a.distance >= 0 ? '+' : ''}${a.distance}`;
        await this.startOp('jog', label, lines, c.commandId);
        return label;
      },
    };
    this.mdi = {
      id: 'g2core.mdi',
      label: 'Send G-code',
      hazard: 'motion',
      role: 'supervisor',
      confirm: false,
      available: (s) => {
        const st = stat(s);
        if (st === null) return 'No status yet';
        if (st === STAT_ALARM || st === STAT_SHUTDOWN || st === STAT_PANIC) return 'Clear the alarm first';
        // Lines sent now would wait behind the motion in progress and run later, maybe unattended:
        // only while idle, or behind this console's own MDI lines (a sequence typed on purpose).
        const job = this.detail
          .getState()
          .jobs.find((j) => j.state.state === 'running' || j.state.state === 'paused');
        if (job) return `Not while job "${job.name ?? job.id}" runs: the lines would wait until it ends`;
        if (IDLE.has(st)) return true;
        const t = this.activeTarget();
        if (t?.kind === 'op' && this.detail.getState().ops[t.id]?.purpose === 'mdi') return true;
        return `Only while idle (the machine is in ${statLabel(st)}): the lines would wait behind the motion`;
      },
      perform: (a, c) => this.sendMdi(a.text, c.commandId),
    };
    this.queueJob = {
      id: 'g2core.queue-job',
      label: 'Queue job',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: async (a, c) => {
        const id = await this.client.createJob(a, c.commandId);
        this.detail.setState({ notice: `"${a.name}" queued as job ${id}. Start it from the queue.` });
        await this.refreshJobs();
        return `job ${id} queued`;
      },
    };
    this.runJob = {
      id: 'g2core.run-job',
      label: 'Start job',
      hazard: 'job',
      role: 'operator',
      confirm: (a) =>
        `Start job "${a.name}"? The machine will move. Check the stock, the tool and the work zero.`,
      available: idle,
      perform: async (a, c) => {
        await this.client.controlJob(a.id, { state: 'run' }, c.commandId);
        await this.refreshJobs();
        this.poller.kick();
        return `job ${a.id} started`;
      },
    };
    this.removeJob = {
      id: 'g2core.remove-job',
      label: 'Remove from queue',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: async (a, c) => {
        await this.client.controlJob(a.id, { state: 'kill' }, c.commandId);
        await this.refreshJobs();
        return `job ${a.id} removed from the queue`;
      },
    };
    this.moveJob = {
      id: 'g2core.move-job',
      label: 'Move in queue',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: async (a, c) => {
        await this.client.controlJob(a.id, { position: a.position }, c.commandId);
        await this.refreshJobs();
        return `job ${a.id} moved to position ${a.position + 1}`;
      },
    };
    this.setSetting = {
      id: 'g2core.set-setting',
      label: 'Change setting',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: false,
      perform: (a, c) => this.writeSetting(a, c.commandId),
    };
    this.setOverride = {
      id: 'g2core.override',
      label: 'Override',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: async (a, c) => {
        const v = await this.client.setKey(null, a.key, a.value, c.commandId);
        this.poller.kick();
        return `${a.key === 'mfo' ? 'feed' : 'spindle'} override ${formatPercent(v)}`;
      },
    };

    const all: CommandDecl<never>[] = [
      this.feedhold,
      this.resume,
      this.kill,
      this.stopJog,
      this.clearAlarm,
      this.home,
      this.jog,
      this.mdi,
      this.queueJob,
      this.runJob,
      this.removeJob,
      this.moveJob,
      this.setSetting,
      this.setOverride,
    ] as CommandDecl<never>[];
    this.commands = Object.fromEntries(all.map((c) => [c.id, c]));
  }

  private retryDelay = 1000;

  start(): void {
    this.poller.start(0);
  }

  stop(): void {
    this.poller.stop();
  }

  stat(): number | null {
    return num(this.detail.getState().sr.stat);
  }

  // ------------------------------------------------------------------------------ polling

  private async poll(): Promise<void> {
    this.polls++;
    if (!this.infoLoaded) await this.loadInfo();
    const sr = this.detail.getState().sr;
    const full = Object.keys(sr).length === 0 || this.polls % FULL_EVERY === 0;
    // Changed-only filter: send the values we have; the controller answers with what differs.
    const update = await this.client.statusReport(full ? undefined : sr);
    const changed = Object.entries(update).some(([k, v]) => sr[k] !== v);
    if (changed) this.detail.setState({ sr: { ...sr, ...update } });
    const slow = this.polls % SLOW_EVERY === 1 || Object.keys(update).includes('stat');
    if (slow) {
      await Promise.all([this.refreshOps(), this.refreshJobs()]);
      await this.adoptForeignOps();
    }
    this.publish();
  }

  private onPollError(e: unknown): void {
    this.retryDelay = this.tracker.fail(e);
  }

  /** Version and axis/override settings, once per connection. */
  private async loadInfo(): Promise<void> {
    try {
      this.detail.setState({ version: await this.client.version() });
    } catch (e) {
      // A server that answers but has no /version still gets a DRO; transport errors count.
      if (!(e instanceof LinkError) || (e.kind !== 'http' && e.kind !== 'vendor')) throw e;
      this.ctx.log.warn('protocol', `GET /version failed: ${describeError(e)}`);
    }
    try {
      const filter: Record<string, Record<string, null> | null> = {};
      for (const a of AXIS_LETTERS) filter[a] = { am: null };
      const tree = await this.client.machine({ ...filter, mfoe: null, ssoe: null });
      const axes = AXIS_LETTERS.filter((a) => {
        const g = tree[a];
        return typeof g === 'object' && g !== null && typeof g.am === 'number' && g.am !== 0;
      });
      const flag = (v: unknown) => (typeof v === 'number' ? v === 1 : typeof v === 'boolean' ? v : null);
      this.detail.setState({
        axes: axes.length > 0 ? axes : ['x', 'y', 'z'],
        overrides: { mfoe: flag(tree.mfoe), ssoe: flag(tree.ssoe) },
      });
    } catch (e) {
      // A server without filters still gets a DRO (x, y, z); say so once.
      this.ctx.log.warn('protocol', `Could not read axis modes: ${describeError(e)}`);
    }
    this.infoLoaded = true;
  }

  private publish(): void {
    const d = this.detail.getState();
    const st = num(d.sr.stat);
    const now = this.ctx.now();
    if (
      st !== null &&
      (st === STAT_ALARM || st === STAT_SHUTDOWN || st === STAT_PANIC || st === STAT_INTERLOCK)
    ) {
      if (!this.alarmSince || this.alarmSince.stat !== st) {
        this.alarmSince = { stat: st, at: now };
        this.ctx.log.error('controller', `Machine state: ${statLabel(st)}`);
      }
    } else this.alarmSince = null;
    const positions: Record<string, number> = {};
    for (const a of d.axes) {
      const v = num(d.sr[`pos${a}`]);
      if (v !== null) positions[a.toUpperCase()] = v;
    }
    const job = this.jobSummary(d.jobs, now);
    const running = d.jobs.find((j) => j.state.state === 'running' || j.state.state === 'paused');
    let label = statLabel(st);
    if (running && st !== null && MOVING.has(st)) label += ` · ${running.name ?? `job ${running.id}`}`;
    // Keep the previous references when nothing changed: views subscribe with shallow selectors.
    const prev = this.ctx.snapshot.getState();
    const same = <T>(a: T, b: T): T => (JSON.stringify(a) === JSON.stringify(b) ? a : b);
    this.tracker.ok({
      activity: activityOf(st),
      activityLabel: label,
      job: same(prev.job, job),
      alarms: same(prev.alarms, alarmsOf(st, this.alarmSince?.at ?? now, this.lastError)),
      positions: same(prev.positions, positions),
      identity: identityOf(d.version),
    });
  }

  private jobSummary(jobs: Job[], now: number): JobSummary | null {
    const j = jobs.find((x) => x.state.state === 'running' || x.state.state === 'paused');
    if (!j) return null;
    const progress =
      j.lines && j.lines > 0 && typeof j.done === 'number' ? Math.min(1, j.done / j.lines) : null;
    const elapsed = j.started !== null ? Math.max(0, (now - j.started) / 1000) : null;
    const remaining =
      progress !== null && progress > 0.02 && elapsed !== null
        ? Math.round((elapsed * (1 - progress)) / progress)
        : null;
    return { name: j.name ?? `job ${j.id}`, progress, elapsed, remaining };
  }

  async refreshJobs(): Promise<void> {
    try {
      const jobs = await this.client.jobs();
      const before = new Map(this.detail.getState().jobs.map((j) => [j.id, j.state.state]));
      for (const j of jobs) {
        const was = before.get(j.id);
        if (was && was !== j.state.state && ['done', 'killed', 'error'].includes(j.state.state)) {
          const msg = j.error ? ` — ${describeStatus(j.error)}` : '';
          this.ctx.log.add(
            j.state.state === 'done' ? 'info' : 'warning',
            'controller',
            `Job "${j.name}" ${j.state.state}${msg}`,
          );
          if (j.error && j.state.state === 'error') this.lastError = describeStatus(j.error);
        }
      }
      const prev = this.detail.getState();
      if (JSON.stringify(prev.jobs) !== JSON.stringify(jobs) || prev.jobsError)
        this.detail.setState({ jobs, jobsError: null });
    } catch (e) {
      this.detail.setState({ jobsError: describeError(e) });
    }
  }

  private async refreshOps(): Promise<void> {
    const ops = Object.values(this.detail.getState().ops).filter((t) => !finished(t.op));
    for (const t of ops) {
      try {
        const op = await this.client.operation(t.id);
        this.updateOp(t.id, op);
      } catch (e) {
        const g = g2StatusOf(e);
        if (g?.code === 100) this.updateOp(t.id, null, true);
      }
    }
  }

  /** False once the server said it has no `GET /operation` (404/405): settled point 8 in client.ts. */
  opsListSupported = true;

  /**
   * The machine moves but nothing this console knows of does (another console's MDI or jog, or
   * a page reloaded mid-move): find the operation with `GET /operation` and track it, so that
   * Feedhold, Cycle start and Kill act on it. Jobs need nothing: every console sees them.
   */
  private async adoptForeignOps(): Promise<void> {
    const d = this.detail.getState();
    const st = num(d.sr.stat);
    if (!this.opsListSupported || st === null || !MOVING.has(st)) return;
    if (d.jobs.some((j) => j.state.state === 'running' || j.state.state === 'paused')) return;
    const moving = (t: TrackedOp) => t.op?.opstate.state === 'run' || t.op?.opstate.state === 'pause';
    if (Object.values(d.ops).some(moving)) return;
    let list: Operation[];
    try {
      list = await this.client.operations();
    } catch (e) {
      if (e instanceof LinkError && (e.status === 404 || e.status === 405)) {
        this.opsListSupported = false;
        this.ctx.log.warn(
          'protocol',
          `GET /operation is not supported (${describeError(e)}): motion started elsewhere cannot be held from here`,
        );
      }
      return;
    }
    const now = this.ctx.now();
    const found: Record<string, TrackedOp> = {};
    list.forEach((op, i) => {
      const state = op.opstate.state;
      if (op.id === undefined || op.optype === 'sendfile') return;
      if (state !== 'run' && state !== 'pause' && state !== 'pend') return;
      const id = String(op.id);
      if (this.detail.getState().ops[id]) return;
      const lines = Array.isArray(op.value)
        ? op.value
        : typeof op.value === 'string'
          ? op.value.split(/\r?\n/)
          : [];
      // Keep the server's order (the running one first) ahead of anything tracked already.
      found[id] = {
        id,
        purpose: 'other',
        label: `operation ${id} (started elsewhere)`,
        lines,
        op,
        startedAt: now - 1_000_000 + i,
      };
    });
    if (Object.keys(found).length === 0) return;
    this.detail.setState((s) => ({ ops: pruneOps({ ...s.ops, ...found }) }));
    this.ctx.log.info(
      'console',
      `Tracking ${Object.values(found)
        .map((t) => t.label)
        .join(', ')}`,
    );
  }

  private updateOp(id: string, op: Operation | null, gone = false): void {
    const t = this.detail.getState().ops[id];
    if (!t) return;
    const was = t.op?.opstate.state;
    const next: TrackedOp = { ...t, op: gone ? { opstate: { state: 'done', raw: 'gone' } } : op };
    this.detail.setState((s) => ({ ops: { ...s.ops, [id]: next } }));
    const now = next.op?.opstate.state;
    if (now !== was && (now === 'done' || now === 'error')) {
      const err = next.op?.error ? describeStatus(next.op.error) : null;
      if (err) {
        this.ctx.log.add(
          next.op?.error?.code === 207 ? 'warning' : 'error',
          'controller',
          `${t.label}: ${err}`,
        );
        if (next.op?.error?.code !== 207) this.lastError = err;
      }
      const replies = next.op?.r?.map((r) => JSON.stringify(r)).join(' ') ?? '';
      if (t.purpose === 'mdi')
        this.updateConsole(id, now === 'done' ? 'done' : 'error', err ?? (replies || null));
      if (t.purpose === 'mdi' && replies) this.ctx.log.info('console', `< ${replies}`);
    } else if (t.purpose === 'mdi' && now === 'run') this.updateConsole(id, 'running', null);
  }

  private updateConsole(opId: string, state: ConsoleEntry['state'], message: string | null): void {
    this.detail.setState((s) => ({
      console: s.console.map((c) => (c.opId === opId ? { ...c, state, message: message ?? c.message } : c)),
    }));
  }

  // ------------------------------------------------------------------------------ commands

  private async startOp(
    purpose: TrackedOp['purpose'],
    label: string,
    lines: string[],
    commandId: string,
  ): Promise<string> {
    const id = await this.client.runOperation(lines, commandId);
    const t: TrackedOp = { id, purpose, label, lines, op: null, startedAt: this.ctx.now() };
    this.detail.setState((s) => ({ ops: pruneOps({ ...s.ops, [id]: t }) }));
    this.poller.kick();
    return id;
  }

  /** The operation a feedhold / cycle start / kill acts on: the running job's, else ours. */
  private activeTarget(): { kind: 'job' | 'op'; id: string; label: string } | null {
    const d = this.detail.getState();
    const job = d.jobs.find((j) => j.state.state === 'running' || j.state.state === 'paused');
    if (job) return { kind: 'job', id: job.id, label: `job "${job.name ?? job.id}"` };
    // The operation in motion (or held) first, else the oldest unfinished one.
    const rank = (t: TrackedOp) => (t.op?.opstate.state === 'run' || t.op?.opstate.state === 'pause' ? 0 : 1);
    const ops = Object.values(d.ops)
      .filter((t) => !finished(t.op))
      .sort((a, b) => rank(a) - rank(b) || a.startedAt - b.startedAt);
    const op = ops[0];
    return op ? { kind: 'op', id: op.id, label: op.label } : null;
  }

  private activeJog(): TrackedOp | null {
    return (
      Object.values(this.detail.getState().ops).find(
        (t) => (t.purpose === 'jog' || t.purpose === 'home') && !finished(t.op),
      ) ?? null
    );
  }

  private async controlActive(what: OpControl, commandId: string): Promise<string> {
    const target = this.activeTarget();
    if (!target) throw new Error('Nothing started from this console is running');
    if (target.kind === 'job') {
      await this.client.controlJob(target.id, { state: what }, commandId);
      await this.refreshJobs();
    } else {
      const op = await this.client.controlOperation(target.id, what, commandId);
      this.updateOp(target.id, op);
      if (what === 'kill') {
        // A kill flushes the queue: every operation behind it is gone too.
        for (const t of Object.values(this.detail.getState().ops))
          if (!finished(t.op)) void this.refreshOne(t.id);
      }
    }
    this.poller.kick();
    const words = { pause: 'held (feedhold)', run: 'resumed (cycle start)', kill: 'killed' }[what];
    return `${target.label} ${words}`;
  }

  private async refreshOne(id: string): Promise<void> {
    try {
      this.updateOp(id, await this.client.operation(id));
    } catch {
      /* the next poll tries again */
    }
  }

  private async sendMdi(text: string, commandId: string): Promise<string> {
    const lines = text
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '');
    if (lines.length === 0) throw new Error('Nothing to send');
    const seq = ++this.consoleSeq;
    const entry: ConsoleEntry = { seq, at: this.ctx.now(), lines, opId: null, state: 'sent', message: null };
    this.detail.setState((s) => ({ console: [...s.console.slice(-99), entry] }));
    try {
      const id = await this.startOp(
        'mdi',
        `MDI ${lines[0]}${lines.length > 1 ? ` (+${lines.length - 1})` : ''}`,
        lines,
        commandId,
      );
      this.detail.setState((s) => ({
        console: s.console.map((c) => (c.seq === seq ? { ...c, opId: id } : c)),
      }));
      this.ctx.log.info('console', `> ${lines.join(' | ')} → operation ${id}`);
      return `operation ${id}`;
    } catch (e) {
      const g = g2StatusOf(e);
      const message = g
        ? `${g.text}${g.additional ? ` — ${g.additional}` : ''} (status ${g.code})`
        : describeError(e);
      this.detail.setState((s) => ({
        console: s.console.map((c) => (c.seq === seq ? { ...c, state: 'refused', message } : c)),
      }));
      this.ctx.log.warn('console', `> ${lines.join(' | ')} refused: ${message}`);
      throw e;
    }
  }

  // ------------------------------------------------------------------------------ settings

  async loadGroups(): Promise<void> {
    try {
      const groups = await this.client.groups();
      this.settings.setState({ groups, groupsError: null });
    } catch (e) {
      this.settings.setState({ groupsError: describeError(e) });
    }
  }

  async loadGroup(name: string): Promise<void> {
    this.settings.setState((s) => ({ loading: { ...s.loading, [name]: true } }));
    try {
      const g = await this.client.group(name);
      this.settings.setState((s) => ({
        values: { ...s.values, [name]: g },
        errors: omit(s.errors, name),
      }));
    } catch (e) {
      this.settings.setState((s) => ({ errors: { ...s.errors, [name]: describeError(e) } }));
    } finally {
      this.settings.setState((s) => ({ loading: omit(s.loading, name) }));
    }
  }

  private async writeSetting(a: SettingArgs, commandId: string): Promise<string> {
    const field = `${a.group}.${a.key}`;
    const group = a.group === 'sys' ? null : a.group;
    try {
      const v = await this.client.setKey(group, a.key, a.value, commandId);
      const value = typeof v === 'object' ? a.value : v;
      this.settings.setState((s) => ({
        values: { ...s.values, [a.group]: { ...s.values[a.group], [a.key]: value as Scalar } },
        fieldErrors: omit(s.fieldErrors, field),
        saved: { ...s.saved, [field]: this.ctx.now() },
      }));
      if (a.group === 'sys' && (a.key === 'mfoe' || a.key === 'ssoe')) this.infoLoaded = false;
      if (a.key === 'am') this.infoLoaded = false;
      return `${a.group === 'sys' ? a.key : `${a.group}${a.key}`} = ${JSON.stringify(value)}`;
    } catch (e) {
      const g = g2StatusOf(e);
      const message = g ? `${g.text}${g.additional ? ` — ${g.additional}` : ''}` : describeError(e);
      this.settings.setState((s) => ({
        fieldErrors: { ...s.fieldErrors, [field]: message },
        refusedReadOnly: g?.code === 104 ? { ...s.refusedReadOnly, [field]: true } : s.refusedReadOnly,
      }));
      throw e;
    }
  }
}

/** Relative jog lines. Kill behaves like M30 (distance mode back to G90), so a stopped jog never leaves G91 behind. */
export function jogLines(a: JogArgs): string[] {
  const d = Number(a.distance.toFixed(4));
  const f = Math.max(1, Math.round(a.feed));
  return [`G91 G1 ${a.axis.toUpperCase()}${d} F${f}`, 'G90'];
}

function finished(op: Operation | null): boolean {
  const s = op?.opstate.state;
  return s === 'done' || s === 'error';
}

function pruneOps(ops: Record<string, TrackedOp>): Record<string, TrackedOp> {
  const list = Object.values(ops);
  if (list.length <= 50) return ops;
  const keep = list.sort((a, b) => b.startedAt - a.startedAt).slice(0, 50);
  return Object.fromEntries(keep.map((t) => [t.id, t]));
}

function omit<T>(r: Record<string, T>, k: string): Record<string, T> {
  const c = { ...r };
  delete c[k];
  return c;
}

export function describeStatus(s: {
  code: number;
  description?: string | undefined;
  additional_description?: string | null | undefined;
}): string {
  const add = s.additional_description ? ` — ${s.additional_description}` : '';
  return `${statusTextOr(s.code, s.description)}${add} (status ${s.code})`;
}

function statusTextOr(code: number, description: string | undefined): string {
  const t = statusText(code);
  return t.startsWith('Status ') && description ? description : t;
}

export function identityOf(v: VersionInfo | null): string | null {
  if (!v) return null;
  const build = v.fbs || (v.fb !== undefined ? String(v.fb) : null);
  const hw = typeof v.hp === 'string' ? v.hp : v.hp !== undefined ? `platform ${v.hp}` : null;
  return ['g2core', build && `build ${build}`, hw].filter(Boolean).join(' · ');
}

export function formatPercent(v: unknown): string {
  return typeof v === 'number' ? `${Math.round(v * 100)} %` : String(v);
}
