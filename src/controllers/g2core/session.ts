import { describeError, LinkError } from '../../fleet/errors';
import { createSharedStore, KernelSession, type Fetcher, type RunToken } from '../../fleet/kernel';
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
import type { Job, SettingsGroup, SrValues, VersionInfo } from './wire';

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
/** A full (unfiltered) status report now and then, in case a changed-only answer was lost. */
const FULL_EVERY = 40;

/** One status poll: identity and axes once per run, then a (changed-only) status report. */
interface StatusRead {
  info: { version: VersionInfo | null; tree: Record<string, unknown> | null; warnings: string[] } | null;
  update: SrValues;
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
  private infoLoaded = false;
  private alarmSince: { stat: number; at: number } | null = null;

  private readonly statusPoll = this.poll<StatusRead>({
    name: 'status',
    read: (signal) => this.readStatus(signal),
    apply: (r) => this.applyStatus(r),
    intervalMs: () => SR_POLL_MS,
  });

  private readonly slowPoll = this.poll<OpsRead>({
    name: 'jobs and operations',
    read: (signal) => this.readSlow(signal),
    apply: (r) => {
      this.ops.apply(r);
      if (this.tracker.state === 'online') this.publish();
    },
    intervalMs: () => SLOW_POLL_MS,
    // The first status report kicks it (its stat is new).
    firstDelayMs: SLOW_POLL_MS,
    when: () => this.tracker.state === 'online',
    // Whether the controller answers is the status poll's to say.
    failed: () => SLOW_POLL_MS,
  });

  private readonly decl = declareCommands(this);
  readonly commands = this.decl.all;
  readonly feedhold = this.decl.feedhold;
  readonly resume = this.decl.resume;
  readonly kill = this.decl.kill;
  readonly stopJog = this.decl.stopJog;
  readonly clearAlarm = this.decl.clearAlarm;
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
    // Version and axes once per run (a restart may face another firmware).
    this.infoLoaded = false;
    this.polls = 0;
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
    const info = this.infoLoaded ? null : await this.readInfo(signal);
    const sr = this.detail.getState().sr;
    const full = Object.keys(sr).length === 0 || this.polls % FULL_EVERY === 0;
    // Changed-only filter: send the values we have; the controller answers with what differs.
    const update = await this.client.statusReport(full ? undefined : sr, signal);
    return { info, update };
  }

  /** Version and axis/override settings. */
  private async readInfo(signal: AbortSignal): Promise<NonNullable<StatusRead['info']>> {
    const warnings: string[] = [];
    let version: VersionInfo | null = null;
    try {
      version = await this.client.version(signal);
    } catch (e) {
      // A server that answers but has no /version still gets a DRO; transport errors count.
      if (!(e instanceof LinkError) || (e.kind !== 'http' && e.kind !== 'vendor')) throw e;
      warnings.push(`GET /version failed: ${describeError(e)}`);
    }
    let tree: Record<string, unknown> | null = null;
    try {
      const filter: Record<string, Record<string, null> | null> = {};
      for (const a of AXIS_LETTERS) filter[a] = { am: null };
      tree = await this.client.machine({ ...filter, mfoe: null, ssoe: null }, signal);
    } catch (e) {
      if (signal.aborted) throw e;
      // A server without filters still gets a DRO (x, y, z); say so once.
      warnings.push(`Could not read axis modes: ${describeError(e)}`);
    }
    return { version, tree, warnings };
  }

  private applyStatus({ info, update }: StatusRead): void {
    if (info) {
      this.infoLoaded = true;
      for (const w of info.warnings) this.ctx.log.warn('protocol', w);
      if (info.version) this.detail.setState({ version: info.version });
      if (info.tree) this.detail.setState(machineInfoOf(info.tree));
    }
    // Structural sharing: an answer that changes nothing notifies nobody.
    this.detail.setState((d) => ({ sr: { ...d.sr, ...update } }));
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
