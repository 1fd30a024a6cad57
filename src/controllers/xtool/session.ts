import type { AnyCommand } from '../../fleet/commands';
import type { SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { createSharedStore, KernelSession, type RunToken } from '../../fleet/kernel';
import { backoffDelay, HIDDEN_POLL_MS, type Poller, type SocketLink } from '../../fleet/link';
import { machineBase } from '../../fleet/origin';
import { READ_TIMEOUT_MS, XtoolClient } from './client';
import { xtoolCommands, type CommandHost, type XtoolCommands } from './commands';
import { asLinkFault, isLinkFault, Liveness, quickRetry } from '../../fleet/faults';
import {
  identityLine,
  initialDetail,
  jobNameAfter,
  snapshotOf,
  type Identity,
  type XtoolDetail,
} from './model';
import { SETTINGS_REFRESH_MS, XtoolReads } from './queries';
import { INITIAL_STATE, alarmForFrame, applyFrame, applyPoll, isBusy, raiseAlarm } from './state';
import {
  LIVENESS_MS,
  POLL_BUSY_MS,
  POLL_IDLE_MS,
  RECHECK_BASE_MS,
  RECHECK_MAX_MS,
  SLOW_ANSWER_FACTOR,
  SLOW_ANSWERS,
  SOCKET_QUIET_MS,
} from './timing';
import { classifyMachineType, frameSchema, type Progress, type WorkingSta } from './wire';

export type { ConsoleEntry, Identity, UploadState, XtoolDetail, XtoolSettings } from './model';
export { initialDetail } from './model';
export type { UploadArgs } from './upload';
export { SETTINGS_REFRESH_MS } from './queries';
export {
  LIVENESS_MS,
  POLL_BUSY_MS,
  POLL_IDLE_MS,
  RECHECK_BASE_MS,
  RECHECK_MAX_MS,
  SLOW_ANSWER_FACTOR,
  SOCKET_QUIET_MS,
} from './timing';

interface StatusRead {
  working: WorkingSta;
  progress: Progress;
  /** When the poll began: a frame that arrived at or after it is newer than its answer. */
  startedAt: number;
  /** `commandsSeen` when the poll began: a command accepted after it is newer than its answer. */
  commands: number;
}

type PollResult =
  | { kind: 'status'; status: StatusRead }
  | { kind: 'connected'; type: string; identity: Omit<Identity, 'type'>; status: StatusRead }
  | { kind: 'unsupported'; type: string | null; answered: string[] };

/**
 * The laser itself answered, whole, if only in words (`{"result":"invalid request"}`), a 404, or
 * JSON of another shape: something is there to identify. A request that failed (no answer, a
 * timeout, the console server's own 502/503/504, a 5xx, a cut answer) is not an answer: it is a
 * link problem and never leads to a verdict.
 */
function answered(e: unknown): e is LinkError {
  if (!(e instanceof LinkError) || isLinkFault(e)) return false;
  return e.kind === 'http' || e.kind === 'vendor' || e.kind === 'protocol';
}

/**
 * One xTool D-series laser on the session kernel. On connect: /ping, identity, get_working_sta,
 * /progress, the settings; then WebSocket frames drive the state and a poll of get_working_sta +
 * /progress runs every 3 s while busy, every 10 s when idle (slower while the page is hidden),
 * never two requests at once (the client's lane). No frame and a failed poll means offline.
 * Commands are in commands.ts, on-demand reads (settings, SD card) in queries.ts.
 */
export class XtoolSession extends KernelSession {
  readonly client: XtoolClient;
  readonly detail = createSharedStore<XtoolDetail>(() => initialDetail());
  readonly reads: XtoolReads;
  readonly poller: Poller;
  readonly commands: Readonly<Record<string, AnyCommand>>;
  private readonly socket: { current: () => SocketLink | null };
  /** Identified and online in this run; false again once offline (identify again on return). */
  private connected = false;
  /** The socket this run opened (it is opened once the laser is known to be a D-series). */
  private opened: SocketLink | null = null;
  /** Counts the commands whose effect the laser accepted (a poll begun before one is older). */
  private commandsSeen = 0;
  /** When this run started (an outage is measured from the last good data or this). */
  private startedAt = 0;
  /** Re-checks of a laser that said it is not a D-series, and the delay before the next one. */
  private rechecks = 0;
  private recheckMs = RECHECK_BASE_MS;
  /** The laser must be heard within its window (LIVENESS_MS): the laser's frames are rare. */
  private readonly liveness: Liveness;
  /** How long the last answers took (SLOW_ANSWERS of them): the window grows on a slow link. */
  private answerMs: number[] = [];

  readonly pause: XtoolCommands['pause'];
  readonly resume: XtoolCommands['resume'];
  readonly stopJob: XtoolCommands['stopJob'];
  readonly upload: XtoolCommands['upload'];
  readonly deleteFile: XtoolCommands['deleteFile'];
  readonly runFile: XtoolCommands['runFile'];
  readonly gcode: XtoolCommands['gcode'];
  readonly setName: XtoolCommands['setName'];
  readonly limitStopOn: XtoolCommands['limitStopOn'];
  readonly limitStopOff: XtoolCommands['limitStopOff'];
  readonly tiltStopOn: XtoolCommands['tiltStopOn'];
  readonly tiltStopOff: XtoolCommands['tiltStopOff'];
  readonly movingStopOn: XtoolCommands['movingStopOn'];
  readonly movingStopOff: XtoolCommands['movingStopOff'];
  readonly tiltThreshold: XtoolCommands['tiltThreshold'];
  readonly movingThreshold: XtoolCommands['movingThreshold'];
  readonly flameMode: XtoolCommands['flameMode'];
  readonly flameSensitivity: XtoolCommands['flameSensitivity'];
  readonly flameAlarmOff: XtoolCommands['flameAlarmOff'];
  readonly upgrade: XtoolCommands['upgrade'];

  constructor(ctx: SessionContext) {
    super(ctx);
    this.client = new XtoolClient(ctx.machine.id, { now: ctx.now });
    this.client.onAnswer = (ms) => this.heard(ms);
    // An upload holds the lane: its progress is the laser taking the bytes, not silence.
    this.client.onTransfer = () => {
      if (this.life.running) this.liveness.heard();
    };
    const host: CommandHost = {
      ctx,
      client: this.client,
      detail: this.detail,
      run: () => this.run(),
      kick: () => this.kick(),
      publish: () => {
        this.commandsSeen++;
        this.tracker.patch(snapshotOf(this.detail.getState()));
      },
    };
    this.reads = new XtoolReads(host);
    this.poller = this.poll<PollResult>({
      name: 'status',
      read: (signal) =>
        this.connected ? this.readStatus(signal).then(statusOnly) : this.readConnect(signal),
      apply: (r) => this.applyRead(r),
      intervalMs: () => (this.rechecking() ? this.recheckMs : this.period()),
      failed: (e) => this.pollFailed(e),
    });
    this.liveness = new Liveness({
      life: this.life,
      now: ctx.now,
      windowMs: () => {
        // The gap between two answers on a slow link: the period after one poll, then an answer.
        const slow = this.period() + Math.max(0, ...this.answerMs) * SLOW_ANSWER_FACTOR;
        const window = Math.min(Math.max(LIVENESS_MS, slow), READ_TIMEOUT_MS + LIVENESS_MS);
        return ctx.visibility.hidden() ? HIDDEN_POLL_MS + window : window;
      },
      onSilent: (quiet) => this.silent(quiet),
    });
    this.socket = this.stream(() => ({
      url: () => `${machineBase(this.machine.id)}/`,
      // Opened once the laser is identified as a D-series (openSocket), not before.
      autoConnect: false,
      heartbeat: {
        silenceMs: SOCKET_QUIET_MS,
        firstMessageMs: SOCKET_QUIET_MS,
        onDead: (why) => {
          this.detail.setState({ socketOpen: false });
          this.ctx.log.add('debug', 'link', `status socket: ${why}; reopening it`);
        },
      },
      onOpen: () => {
        this.detail.setState({ socketOpen: true });
        this.ctx.log.info('link', 'status socket open');
      },
      onClose: () => {
        if (this.detail.getState().socketOpen)
          this.ctx.log.warn('link', 'status socket closed; reconnecting');
        this.detail.setState({ socketOpen: false });
      },
      onMessage: (data) => this.onFrame(data),
    }));
    const c = xtoolCommands(host);
    this.commands = c.all;
    this.pause = c.pause;
    this.resume = c.resume;
    this.stopJob = c.stopJob;
    this.upload = c.upload;
    this.deleteFile = c.deleteFile;
    this.runFile = c.runFile;
    this.gcode = c.gcode;
    this.setName = c.setName;
    this.limitStopOn = c.limitStopOn;
    this.limitStopOff = c.limitStopOff;
    this.tiltStopOn = c.tiltStopOn;
    this.tiltStopOff = c.tiltStopOff;
    this.movingStopOn = c.movingStopOn;
    this.movingStopOff = c.movingStopOff;
    this.tiltThreshold = c.tiltThreshold;
    this.movingThreshold = c.movingThreshold;
    this.flameMode = c.flameMode;
    this.flameSensitivity = c.flameSensitivity;
    this.flameAlarmOff = c.flameAlarmOff;
    this.upgrade = c.upgrade;
  }

  protected override onStart(): void {
    this.connected = false;
    this.opened = null;
    this.startedAt = this.ctx.now();
    this.rechecks = 0;
    this.answerMs = [];
    this.detail.setState({ socketOpen: false });
    this.liveness.start();
  }

  /** A laser that said it is another model: asked again on the recheck backoff only. */
  private rechecking(): boolean {
    return !this.connected && this.detail.getState().model.family === 'unsupported';
  }

  private period(): number {
    return isBusy(this.detail.getState().machine.state) ? POLL_BUSY_MS : POLL_IDLE_MS;
  }

  /** Poll now, or right after the poll in flight (a command or an acknowledgement changed things). */
  kick(): void {
    this.poller.kick();
  }

  // --- connecting and polling ---------------------------------------------------------------

  /** Connect, in the order of the README: ping, identify, identity, a first poll, the settings. */
  private async readConnect(signal: AbortSignal): Promise<PollResult> {
    const { client } = this;
    const run = this.run();
    await client.ping(signal).catch((e: unknown) => {
      // Another xTool family may not know /ping at all; it answered, so identify it.
      if (!answered(e)) throw e;
    });
    let type: string | null = null;
    let said: string | null = null;
    try {
      type = (await client.machineType(signal)).type;
    } catch (e) {
      if (!answered(e)) throw e;
      said = `/getmachinetype → ${e.message}`;
    }
    if (type === null || classifyMachineType(type) !== 'd-series') {
      // Not a D-series: show what it said (and what /status says, the REST V1 of F1/P2/M1).
      const lines = [type !== null ? `/getmachinetype → type "${type}"` : (said ?? '')];
      lines.push(await client.probe('/status', signal));
      return { kind: 'unsupported', type, answered: lines };
    }
    const optional = <T>(what: string, p: Promise<T>): Promise<T | null> =>
      p.catch((e: unknown) => {
        // The laser said it has no such value; a failed request is the link's, not "no value".
        if (e instanceof LinkError && !isLinkFault(e) && (e.kind === 'vendor' || e.kind === 'protocol')) {
          if (run.alive()) this.ctx.log.warn('protocol', `${what}: ${e.message}`);
          return null;
        }
        throw e;
      });
    const power = await optional('laser power', client.laserPowerType(signal));
    const powerInfo = await optional('laser module', client.laserPowerInfo(signal));
    const version = await optional('firmware version', client.version(signal));
    const mac = await optional('MAC address', client.mac(signal));
    const name = await optional('device name', client.deviceName(signal));
    const status = await this.readStatus(signal);
    await this.reads.refreshSettings(0);
    const identity = {
      power: power?.power ?? powerInfo?.power ?? null,
      powerInfoType: powerInfo?.type ?? null,
      version: version?.version ?? null,
      sn: version?.sn ?? null,
      mac: mac?.mac ?? null,
      name: name?.name ?? null,
    };
    return { kind: 'connected', type, identity, status };
  }

  /** get_working_sta + /progress; while the laser is idle, the settings when they are stale. */
  private async readStatus(signal: AbortSignal): Promise<StatusRead> {
    const run = this.run();
    const startedAt = this.ctx.now();
    const commands = this.commandsSeen;
    const working = await this.client.workingSta(signal);
    this.confirm(run, working, startedAt, commands);
    const progress = await this.client.progress(signal);
    const s = this.detail.getState();
    if (this.connected && !isBusy(applyPoll(s.machine, working.code, progress, s.progress).state)) {
      await this.reads.refreshSettings(SETTINGS_REFRESH_MS);
    }
    return { working, progress, startedAt, commands };
  }

  /** The laser answered (client.ts onAnswer): it is heard, and how long it took sizes the window. */
  private heard(ms: number): void {
    if (!this.life.running) return;
    this.answerMs.push(ms);
    if (this.answerMs.length > SLOW_ANSWERS) this.answerMs.shift();
    this.liveness.heard();
  }

  /**
   * The working state answered, and it is what the laser said last time (nothing newer came
   * meanwhile): the state shown is confirmed now. On a slow link /progress comes seconds later; a
   * late answer is still data. A change waits for /progress (the state may depend on it).
   */
  private confirm(run: RunToken, working: WorkingSta, startedAt: number, commands: number): void {
    if (!this.connected || !run.alive()) return;
    // Fresh data while online, or the end of a silence or a timeout; a failure of another kind
    // (a protocol error of /progress, a refusal) ends only with a whole poll.
    const link = this.ctx.snapshot.getState();
    if (link.link !== 'online' && link.problem?.kind !== 'timeout') return;
    const s = this.detail.getState();
    if (s.working?.code !== working.code || this.commandsSeen !== commands) return;
    if (s.lastFrame !== null && s.lastFrame.at >= startedAt) return;
    this.tracker.ok(snapshotOf(s));
  }

  private applyRead(r: PollResult): void {
    switch (r.kind) {
      case 'status':
        this.applyStatus(r.status);
        return;
      case 'connected':
        this.rechecks = 0;
        this.detail.setState((s) => ({
          model: { family: 'd-series', answered: [] },
          identity: { ...s.identity, ...r.identity, type: r.type },
        }));
        this.applyStatus(r.status);
        this.connected = true;
        this.tracker.ok({ identity: identityLine(this.detail.getState().identity) });
        this.openSocket();
        return;
      case 'unsupported':
        this.unsupported(r.type, r.answered);
        return;
    }
  }

  private applyStatus({ working, progress, startedAt, commands }: StatusRead): void {
    const s = this.detail.getState();
    // A frame, or a command the laser accepted, that came while this poll was in flight is newer
    // than the poll: it wins (the poll may have read the state before a remote start).
    const frameWins = s.lastFrame !== null && s.lastFrame.at >= startedAt;
    const newer = frameWins || this.commandsSeen !== commands;
    const machine = newer ? s.machine : applyPoll(s.machine, working.code, progress, s.progress);
    if (working.code === 'unknown') this.ctx.log.warn('protocol', `Unknown working state "${working.raw}"`);
    this.detail.setState({
      working,
      progress,
      machine,
      source: newer ? s.source : 'poll',
      jobName: newer ? s.jobName : jobNameAfter(s.jobName, machine),
    });
    const snap = snapshotOf(this.detail.getState());
    if (this.connected) this.tracker.ok(snap);
    else this.tracker.patch(snap);
  }

  /**
   * Another xTool model (a complete answer of its own said so): say so with what it answered, and
   * ask again on a slow backoff (RECHECK_*): the verdict is re-checked, never final.
   */
  private unsupported(type: string | null, lines: string[]): void {
    this.recheckMs = backoffDelay(this.rechecks++, { baseMs: RECHECK_BASE_MS, maxMs: RECHECK_MAX_MS });
    this.detail.setState((s) => ({
      model: { family: 'unsupported', answered: lines },
      identity: { ...s.identity, type },
    }));
    const model = type ?? 'an xTool that does not speak the D-series protocol';
    const message = `Unsupported model: ${model}. This console speaks the D-series (D1, D1 Pro, D1 Pro 2.0) protocol only.`;
    const was = this.ctx.snapshot.getState();
    this.ctx.snapshot.setState({
      link: 'protocol-error',
      problem: { kind: 'protocol', message },
      retryAt: this.ctx.now() + this.recheckMs,
      activity: 'unknown',
      activityLabel: 'Unsupported model',
      identity: type,
      updatedAt: this.ctx.now(),
    });
    if (was.link !== 'protocol-error' || was.problem?.message !== message)
      this.ctx.log.error('protocol', `${message} The device answered: ${lines.join(' | ')}`);
  }

  private pollFailed(e: unknown): number {
    // A powered-off laser is offline, not an error: with no socket either, the first failure says so.
    const socketUp = this.socket.current()?.open ?? false;
    this.tracker.fail(asLinkFault(e), { offlineAfter: socketUp ? 3 : 1 });
    if (this.tracker.state === 'offline') {
      // Identify again when it comes back: it may have been power-cycled or swapped.
      this.connected = false;
      this.detail.setState({ machine: INITIAL_STATE, source: null });
    }
    // Quick retries while the outage is young: back within 5 s of the fault ending.
    return quickRetry(this.ctx, this.tracker, this.startedAt);
  }

  /** The poll did not answer within its window: the link is in doubt now, not at the timeout. */
  private silent(quietMs: number): void {
    if (this.tracker.state !== 'online') return;
    this.tracker.fail(
      new LinkError('timeout', `The laser has not answered for ${Math.round(quietMs / 1000)} s`),
      { offlineAfter: 3 },
    );
    // The poll in flight is still waiting for its answer: no "next try" time to show.
    this.tracker.patch({ retryAt: null });
  }

  // --- the WebSocket ------------------------------------------------------------------------

  /**
   * Online: open the status socket the first time. Back after being offline, a socket that stayed
   * open all along is reopened: it may be a TCP connection to a laser that was switched off and on,
   * which never speaks again and never closes.
   */
  private openSocket(): void {
    const link = this.socket.current();
    if (!link) return;
    if (this.opened !== link) {
      this.opened = link;
      link.connect();
    } else if (link.open) {
      this.detail.setState({ socketOpen: false });
      link.restart();
    }
  }

  /** One WebSocket frame. Public for tests that drive the state machine. */
  onFrame(data: string): void {
    const parsed = frameSchema.safeParse(data);
    if (!parsed.success) return;
    const f = parsed.data;
    const at = this.ctx.now();
    if (f.kind === 'unknown') {
      this.ctx.log.warn('controller', `Unknown frame "${f.raw}"`);
      this.detail.setState({ lastFrame: { raw: f.raw, at } });
      return;
    }
    const before = this.detail.getState().machine;
    const machine = applyFrame(before, f);
    this.detail.setState((s) => ({
      machine,
      lastFrame: { raw: f.raw, at },
      source: 'socket',
      jobName: jobNameAfter(s.jobName, machine),
    }));
    this.ctx.log.add(f.kind === 'sensor' || f.kind === 'error' ? 'error' : 'info', 'controller', f.raw);
    const alarm = alarmForFrame(f, at);
    const alarms = alarm ? raiseAlarm(this.ctx.snapshot.getState().alarms, alarm) : undefined;
    this.tracker.patch({
      ...snapshotOf(this.detail.getState()),
      ...(alarms ? { alarms } : {}),
      updatedAt: at,
    });
    if (machine.state === 'job-loaded' || machine.state === 'frame-ready') {
      this.detail.setState({
        notice: 'The laser is waiting: the job starts with the button on the machine.',
      });
    }
    // Busy-ness changed, or the laser is back while we thought it gone: poll now.
    if (isBusy(before.state) !== isBusy(machine.state) || this.tracker.state !== 'online') this.kick();
  }

  acknowledgeAlarm(alarmId: string): void {
    const alarms = this.ctx.snapshot.getState().alarms;
    const a = alarms.find((x) => x.id === alarmId);
    if (!a) return;
    // The D-series has no alarm acknowledgement of its own: this is the console's.
    this.ctx.snapshot.setState({ alarms: alarms.filter((x) => x.id !== alarmId) });
    this.ctx.log.info('console', `Alarm acknowledged: ${a.message}`);
    const m = this.detail.getState().machine;
    if ((m.state === 'alarm' || m.state === 'error') && !this.ctx.snapshot.getState().alarms.length) {
      // The job was aborted; the next poll says what the laser does now.
      this.kick();
    }
  }
}

function statusOnly(status: StatusRead): PollResult {
  return { kind: 'status', status };
}
