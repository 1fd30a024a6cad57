import { describeError, LinkError } from '../../fleet/errors';
import { asLinkFault, isLinkFault, Liveness, quickRetry } from '../../fleet/faults';
import { createSharedStore, KernelSession, type Fetcher, type RunToken } from '../../fleet/kernel';
import { HIDDEN_POLL_MS } from '../../fleet/link';
import { STAT_ALARM, STAT_INTERLOCK, STAT_PANIC, STAT_SHUTDOWN, statLabel } from './codes';
import { G2coreClient, g2StatusOf } from './client';
import { declareCommands, type CommandHost } from './commands';
import {
  AXIS_LETTERS,
  activityLabelOf,
  activityOf,
  alarmsOf,
  describeStatus,
  identityOf,
  initialDetail,
  initialSettings,
  jobSummary,
  machineInfoOf,
  num,
  omit,
  positionsOf,
  type G2Detail,
  type SettingArgs,
  type SettingsState,
} from './model';
import { OpTracker, type OpsRead } from './operations';
import { GROUP_STALE_MS, GROUPS_STALE_MS, JOBS_KEY, SETTINGS_GROUPS_KEY, settingsGroupKey } from './queries';
import type { Job, Scalar, SettingsGroup, SrValues, VersionInfo } from './wire';

export {
  AXIS_LETTERS,
  activityOf,
  alarmsOf,
  describeStatus,
  formatPercent,
  identityOf,
  initialDetail,
  jogLines,
  type AxisLetter,
  type ConsoleEntry,
  type G2Detail,
  type JogArgs,
  type SettingArgs,
  type SettingsState,
  type TrackedOp,
} from './model';

/** Status reports about 4 per second while the page is visible (the poll slows down when hidden). */
export const SR_POLL_MS = 250;
/** Job list and tracked operations about once a second, and at once when `stat` changes. */
export const SLOW_POLL_MS = 1000;
/** The same two reads when only a fleet tile shows the machine (no machine page open). */
export const TILE_POLL_MS = 1000;
export const TILE_SLOW_POLL_MS = 2000;
/** A full (unfiltered) status report now and then, in case a changed-only answer was lost. */
const FULL_EVERY = 40;
/**
 * The status report's window (issue 15): no good report for this long (about 12 polls) is a silent
 * link, shown as down at once rather than at the request's own timeout (5 s). While the page is
 * hidden the poll runs every 10 s or more, and the window grows with it.
 */
export const LIVENESS_MS = 3000;

/** One status poll: identity and axes once per run, then a (changed-only) status report. */
interface StatusRead {
  info: { version: VersionInfo | null; tree: Record<string, unknown> | null; warnings: string[] } | null;
  update: SrValues;
  /** An unfiltered report: every key the report is configured with (it replaces what we hold). */
  full: boolean;
}

/** Longest changed-only filter sent (as JSON); beyond it the report is read in full. */
const MAX_FILTER_CHARS = 2000;
/** A text value longer than this is selected (null), not echoed back to the controller. */
const MAX_FILTER_TEXT = 64;

/** The changed-only filter of the values we hold, or null when it would not fit in a URL. */
export function filterOf(sr: SrValues): Record<string, Scalar> | null {
  const filter: Record<string, Scalar> = {};
  for (const [k, v] of Object.entries(sr))
    filter[k] = typeof v === 'string' && v.length > MAX_FILTER_TEXT ? null : v;
  return JSON.stringify(filter).length <= MAX_FILTER_CHARS ? filter : null;
}

/**
 * A g2core controller over the REST design (README.md). Two polls: the status report (changed
 * keys only, about 4 per second) and, about once a second or when the state changes, the job
 * list (through the query layer, shared with the Jobs tab) and the operations this console
 * tracks (operations.ts). No socket: the design has none. The kernel owns when the polls run,
 * that nothing is written after stop, and the kick after a command; the commands are declared
 * in commands.ts, the data mapping is in model.ts, the on-demand reads in queries.ts.
 */
export class G2coreSession extends KernelSession implements CommandHost {
  readonly client = new G2coreClient(this.machine.id);
  readonly detail = createSharedStore<G2Detail>(() => initialDetail());
  readonly settings = createSharedStore<SettingsState>(() => initialSettings());
  readonly ops = new OpTracker({
    ctx: this.ctx,
    client: this.client,
    detail: this.detail,
    run: () => this.run(),
    refresh: (jobs) => this.refresh(jobs),
  });

  private polls = 0;
  /** Version and axes read since the link last failed: verdicts are re-checked on every reconnect. */
  private infoLoaded = false;
  private alarmSince: { stat: number; at: number } | null = null;
  /** When this run started (an outage is measured from the last good data or this). */
  private startedAt = 0;
  /** The status report must answer within its window (LIVENESS_MS). */
  private readonly liveness = new Liveness({
    life: this.life,
    now: this.ctx.now,
    windowMs: () => (this.ctx.visibility.hidden() ? HIDDEN_POLL_MS + LIVENESS_MS : LIVENESS_MS),
    onSilent: (quiet) => this.silent(quiet),
  });

  private readonly statusPoll = this.poll<StatusRead>({
    name: 'status',
    read: (signal) => this.readStatus(signal),
    apply: (r) => this.applyStatus(r),
    // 4 Hz for the machine page (positions); once a second for a fleet tile.
    intervalMs: () => (this.ctx.detail() ? SR_POLL_MS : TILE_POLL_MS),
    failed: (e) => this.statusFailed(e),
  });

  private readonly slowPoll = this.poll<OpsRead>({
    name: 'jobs and operations',
    read: (signal) => this.readSlow(signal),
    apply: (r) => {
      this.ops.apply(r);
      if (this.tracker.state === 'online') this.publish();
    },
    intervalMs: () => (this.ctx.detail() ? SLOW_POLL_MS : TILE_SLOW_POLL_MS),
    // The first status report kicks it (its stat is new).
    firstDelayMs: SLOW_POLL_MS,
    when: () => this.tracker.state === 'online',
    // Whether the controller answers is the status poll's to say; an answer it could not use is logged.
    failed: (e) => {
      if (!(e instanceof LinkError))
        this.ctx.log.error('protocol', `Could not use the jobs and operations read: ${describeError(e)}`);
      return SLOW_POLL_MS;
    },
  });

  private readonly decl = declareCommands(this);
  readonly commands = this.decl.all;
  readonly feedhold = this.decl.feedhold;
  readonly resume = this.decl.resume;
  readonly kill = this.decl.kill;
  readonly stopJog = this.decl.stopJog;
  readonly clearAlarm = this.decl.clearAlarm;
  readonly resetBoard = this.decl.resetBoard;
  readonly home = this.decl.home;
  readonly jog = this.decl.jog;
  readonly mdi = this.decl.mdi;
  readonly queueJob = this.decl.queueJob;
  readonly runJob = this.decl.runJob;
  readonly removeJob = this.decl.removeJob;
  readonly moveJob = this.decl.moveJob;
  readonly setSetting = this.decl.setSetting;
  readonly setOverride = this.decl.setOverride;

  /** False once the server said it has no `GET /operation` (404/405): settled point 8 in client.ts. */
  get opsListSupported(): boolean {
    return this.detail.getState().opsList;
  }

  stat(): number | null {
    return num(this.detail.getState().sr.stat);
  }

  protected override onStart(): void {
    // Version and axes once per run and per reconnect (a restart may face another firmware).
    this.infoLoaded = false;
    this.polls = 0;
    this.startedAt = this.ctx.now();
    this.liveness.start();
  }

  /**
   * A failed status read: a request that got no whole answer (no answer, a timeout, the console
   * server's failure, a 5xx, a cut answer) is a link problem; a whole answer of the wrong shape a
   * protocol error. Retried quickly while the outage is young; version and axes are read again.
   */
  private statusFailed(e: unknown): number {
    this.infoLoaded = false;
    // HttpClient turns every transport failure into a LinkError: anything else is an answer this
    // console could not use (a protocol error in words), never a link problem.
    this.tracker.fail(
      e instanceof LinkError
        ? asLinkFault(e)
        : new LinkError('protocol', `Could not use the status report: ${describeError(e)}`),
    );
    return quickRetry(this.ctx, this.tracker, this.startedAt);
  }

  /** No status report within the window: the link is in doubt now, not at the request's timeout. */
  private silent(quietMs: number): void {
    if (this.tracker.state !== 'online') return;
    this.infoLoaded = false;
    this.tracker.fail(
      new LinkError('timeout', `The controller has not answered for ${Math.round(quietMs / 1000)} s`),
    );
    // The read in flight is still waiting for its answer: no "next try" time to show.
    this.tracker.patch({ retryAt: null });
  }

  /** Public for the commands (commands.ts): the run a command's answer belongs to. */
  override run(): RunToken {
    return super.run();
  }

  refresh(jobs = false): void {
    this.statusPoll.kick();
    if (jobs) this.slowPoll.kick();
  }

  // ------------------------------------------------------------------------------ on-demand reads

  /** The job list (query key `['jobs']`): written into `detail` while the run that read it is current. */
  readonly readJobs: Fetcher<Job[]> = async (signal) => {
    const run = this.run();
    const jobs = await this.client.jobs(signal);
    if (run.alive()) this.applyJobs(jobs);
    return jobs;
  };

  readonly readGroups: Fetcher<string[]> = (signal) => this.client.groups(signal);

  readGroup(name: string): Fetcher<SettingsGroup> {
    return (signal) => this.client.group(name, signal);
  }

  /** The machine's top-level groups (cached: queries.ts). */
  loadGroups(): Promise<string[]> {
    return this.ctx.queries.fetch(SETTINGS_GROUPS_KEY, this.readGroups, { staleTimeMs: GROUPS_STALE_MS });
  }

  /** One group's values (cached; a settings write makes it stale). */
  loadGroup(name: string): Promise<SettingsGroup> {
    return this.ctx.queries.fetch(settingsGroupKey(name), this.readGroup(name), {
      staleTimeMs: GROUP_STALE_MS,
    });
  }

  // ------------------------------------------------------------------------------ status poll

  private async readStatus(signal: AbortSignal): Promise<StatusRead> {
    this.polls++;
    const sr = this.detail.getState().sr;
    // Changed-only filter: send the values we have; the controller answers with what differs.
    const filter = filterOf(sr);
    // A full report on (re)connect (the values we hold may be from before the outage), now and
    // then, and when the values we hold would not fit in a URL.
    const full =
      !this.infoLoaded || filter === null || Object.keys(sr).length === 0 || this.polls % FULL_EVERY === 0;
    // Version and axes alongside, on (re)connect: one round trip, not three.
    const [info, update] = await Promise.all([
      this.infoLoaded ? null : this.readInfo(signal),
      this.client.statusReport(full || filter === null ? undefined : filter, signal),
    ]);
    return { info, update, full };
  }

  /**
   * Version and axis/override settings. Only the controller's own whole answer says it has no
   * `/version` or no filters; a request that failed is the link's (thrown: the poll retries).
   */
  private async readInfo(signal: AbortSignal): Promise<NonNullable<StatusRead['info']>> {
    const warnings: string[] = [];
    const filter: Record<string, Record<string, null> | null> = {};
    for (const a of AXIS_LETTERS) filter[a] = { am: null };
    const [version, tree] = await Promise.all([
      this.client.version(signal).catch((e: unknown): VersionInfo | null => {
        // A server that answers but has no /version still gets a DRO.
        if (!(e instanceof LinkError) || isLinkFault(e) || (e.kind !== 'http' && e.kind !== 'vendor'))
          throw e;
        warnings.push(`GET /version failed: ${describeError(e)}`);
        return null;
      }),
      this.client
        .machine({ ...filter, mfoe: null, ssoe: null }, signal)
        .catch((e: unknown): Record<string, unknown> | null => {
          if (signal.aborted || isLinkFault(e)) throw e;
          // A server without filters still gets a DRO (x, y, z); say so once.
          warnings.push(`Could not read axis modes: ${describeError(e)}`);
          return null;
        }),
    ]);
    return { version, tree, warnings };
  }

  private applyStatus({ info, update, full }: StatusRead): void {
    this.liveness.heard();
    if (info) {
      this.infoLoaded = true;
      for (const w of info.warnings) this.ctx.log.warn('protocol', w);
      if (info.version) this.detail.setState({ version: info.version });
      if (info.tree) this.detail.setState(machineInfoOf(info.tree));
      // "No GET /operation" is asked again after a reconnect (another server may answer now).
      if (!this.detail.getState().opsList) this.detail.setState({ opsList: true });
    }
    // Structural sharing: an answer that changes nothing notifies nobody. A full report is the
    // whole state (keys it no longer has are dropped); a changed-only one is merged.
    this.detail.setState((d) => ({ sr: full ? update : { ...d.sr, ...update } }));
    this.publish();
    // A new state: read the jobs and operations now rather than up to a second later.
    if ('stat' in update) this.slowPoll.kick();
  }

  private publish(): void {
    const d = this.detail.getState();
    const st = num(d.sr.stat);
    const now = this.ctx.now();
    if (st === STAT_ALARM || st === STAT_SHUTDOWN || st === STAT_PANIC || st === STAT_INTERLOCK) {
      if (this.alarmSince?.stat !== st) {
        this.alarmSince = { stat: st, at: now };
        this.ctx.log.error('controller', `Machine state: ${statLabel(st)}`);
      }
    } else this.alarmSince = null;
    // The snapshot store shares structure: unchanged parts keep their identity.
    this.tracker.ok({
      activity: activityOf(st),
      activityLabel: activityLabelOf(st, d.jobs),
      job: jobSummary(d.jobs, now),
      alarms: alarmsOf(st, this.alarmSince?.at ?? now, d.lastError),
      positions: positionsOf(d),
      identity: identityOf(d.version),
    });
  }

  // ------------------------------------------------------------------------------ slow poll

  private async readSlow(signal: AbortSignal): Promise<OpsRead> {
    const [ops] = await Promise.all([
      this.ops.readTracked(signal),
      // A fresh read each time (a state change must see the job that caused it), shared with a
      // read of the Jobs tab in flight; a failed read shows there (the query's error).
      this.ctx.queries.fetch(JOBS_KEY, this.readJobs, { staleTimeMs: 0 }).catch(() => null),
    ]);
    return { ops, foreign: await this.ops.readForeign(ops, signal) };
  }

  private applyJobs(jobs: Job[]): void {
    const before = new Map(this.detail.getState().jobs.map((j) => [j.id, j.state.state]));
    let lastError: string | null = null;
    for (const j of jobs) {
      const was = before.get(j.id);
      if (was && was !== j.state.state && ['done', 'killed', 'error'].includes(j.state.state)) {
        const msg = j.error ? ` — ${describeStatus(j.error)}` : '';
        const level = j.state.state === 'done' ? 'info' : 'warning';
        this.ctx.log.add(level, 'controller', `Job "${j.name}" ${j.state.state}${msg}`);
        if (j.error && j.state.state === 'error') lastError = describeStatus(j.error);
      }
    }
    this.detail.setState(lastError ? { jobs, lastError } : { jobs });
  }

  // ------------------------------------------------------------------------------ settings

  async writeSetting(a: SettingArgs, commandId: string): Promise<string> {
    const run = this.run();
    const field = `${a.group}.${a.key}`;
    const group = a.group === 'sys' ? null : a.group;
    try {
      const v = await this.client.setKey(group, a.key, a.value, commandId);
      const value = typeof v === 'object' ? a.value : v;
      if (run.alive()) {
        this.settings.setState((s) => ({
          fieldErrors: omit(s.fieldErrors, field),
          saved: { ...s.saved, [field]: this.ctx.now() },
        }));
        // Axes and override switches are read again with the next status poll.
        if ((a.group === 'sys' && (a.key === 'mfoe' || a.key === 'ssoe')) || a.key === 'am')
          this.infoLoaded = false;
      }
      return `${a.group === 'sys' ? a.key : `${a.group}${a.key}`} = ${JSON.stringify(value)}`;
    } catch (e) {
      const g = g2StatusOf(e);
      const message = g ? `${g.text}${g.additional ? ` — ${g.additional}` : ''}` : describeError(e);
      if (run.alive())
        this.settings.setState((s) => ({
          fieldErrors: { ...s.fieldErrors, [field]: message },
          refusedReadOnly: g?.code === 104 ? { ...s.refusedReadOnly, [field]: true } : s.refusedReadOnly,
        }));
      throw e;
    }
  }
}
