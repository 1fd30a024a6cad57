import type { AnyCommand } from '../../fleet/commands';
import type { SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { createSharedStore, KernelSession } from '../../fleet/kernel';
import type { Poller, SocketLink } from '../../fleet/link';
import { machineBase } from '../../fleet/origin';
import { XtoolClient } from './client';
import { xtoolCommands, type CommandHost, type XtoolCommands } from './commands';
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
import { classifyMachineType, frameSchema, type Progress, type WorkingSta } from './wire';

export type { ConsoleEntry, Identity, UploadState, XtoolDetail, XtoolSettings } from './model';
export { initialDetail } from './model';
export type { UploadArgs } from './upload';
export { SETTINGS_REFRESH_MS } from './queries';

/** Poll intervals (issue 4): every 3 s while a job is loaded or running, every 10 s when idle. */
export const POLL_BUSY_MS = 3000;
export const POLL_IDLE_MS = 10_000;
/**
 * The status socket's heartbeat policy. The laser speaks on :8081 only when its state changes
 * (nothing on connect, no ping it answers), so silence proves nothing either way: a healthy
 * socket of an idle laser and a dead TCP connection (the laser was switched off and on, the WiFi
 * dropped) look the same. A socket quiet this long is reopened; the polls keep the state meanwhile.
 */
export const SOCKET_QUIET_MS = 5 * 60_000;

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

/** It answered, if only in words or with a body we cannot read: something is there to identify. */
function answered(e: unknown): e is LinkError {
  return e instanceof LinkError && (e.kind === 'http' || e.kind === 'vendor' || e.kind === 'protocol');
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
    this.client = new XtoolClient(ctx.machine.id);
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
      intervalMs: () => (isBusy(this.detail.getState().machine.state) ? POLL_BUSY_MS : POLL_IDLE_MS),
      failed: (e) => this.pollFailed(e),
    });
    this.socket = this.stream(() => ({
      url: () => `${machineBase(this.machine.id)}/`,
      // Opened once the laser is identified as a D-series (openSocket), not before.
      autoConnect: false,
      heartbeat: {
        silenceMs: SOCKET_QUIET_MS,
        firstMessageMs: SOCKET_QUIET_MS,
        checkEveryMs: 5000,
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
    this.detail.setState({ socketOpen: false });
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
        if (e instanceof LinkError && (e.kind === 'vendor' || e.kind === 'protocol')) {
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
    const startedAt = this.ctx.now();
    const commands = this.commandsSeen;
    const working = await this.client.workingSta(signal);
    const progress = await this.client.progress(signal);
    const s = this.detail.getState();
    if (this.connected && !isBusy(applyPoll(s.machine, working.code, progress, s.progress).state)) {
      await this.reads.refreshSettings(SETTINGS_REFRESH_MS);
    }
    return { working, progress, startedAt, commands };
  }

  private applyRead(r: PollResult): void {
    switch (r.kind) {
      case 'status':
        this.applyStatus(r.status);
        return;
      case 'connected':
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

  /** Another xTool model: say so with what it answered, and stop talking to it. */
  private unsupported(type: string | null, lines: string[]): void {
    this.detail.setState((s) => ({
      model: { family: 'unsupported', answered: lines },
      identity: { ...s.identity, type },
    }));
    const model = type ?? 'an xTool that does not speak the D-series protocol';
    const message = `Unsupported model: ${model}. This console speaks the D-series (D1, D1 Pro, D1 Pro 2.0) protocol only.`;
    this.ctx.snapshot.setState({
      link: 'protocol-error',
      problem: { kind: 'protocol', message },
      retryAt: null,
      activity: 'unknown',
      activityLabel: 'Unsupported model',
      identity: type,
      updatedAt: this.ctx.now(),
    });
    this.ctx.log.error('protocol', `${message} The device answered: ${lines.join(' | ')}`);
    this.stop();
  }

  private pollFailed(e: unknown): number {
    // A powered-off laser is offline, not an error: with no socket either, the first failure says so.
    const socketUp = this.socket.current()?.open ?? false;
    const delay = this.tracker.fail(e, { offlineAfter: socketUp ? 3 : 1 });
    if (this.tracker.state === 'offline') {
      // Identify again when it comes back: it may have been power-cycled or swapped.
      this.connected = false;
      this.detail.setState({ machine: INITIAL_STATE, source: null });
    }
    return delay;
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
