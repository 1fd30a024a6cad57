import { createStore, type StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../../fleet/contract';
import { LinkError, describeError } from '../../fleet/errors';
import { Poller, SocketLink } from '../../fleet/link';
import { machineBase } from '../../fleet/origin';
import type { MachineInfo, MachineSnapshot } from '../../fleet/types';
import { XtoolClient, uploadPath, type SwitchAction, type UploadTarget } from './client';
import {
  INITIAL_STATE,
  alarmForFrame,
  applyFrame,
  applyJobAction,
  applyPoll,
  isBusy,
  isRunningJob,
  jobSummary,
  raiseAlarm,
  stateLabel,
  toActivity,
  type MachineState,
} from './state';
import {
  classifyMachineType,
  flameSensitivityWords,
  frameSchema,
  type PeripheryStatus,
  type Progress,
  type WorkingSta,
} from './wire';

/** Poll intervals (issue 4): every 3 s while a job is loaded or running, every 10 s when idle. */
export const POLL_BUSY_MS = 3000;
export const POLL_IDLE_MS = 10_000;
/**
 * Settings (/peripherystatus: SD card, safety switches, flame alarm) are re-read this often while
 * the laser is idle: the vendor app or the machine itself may change them, and a safety page
 * showing "flame alarm: high" after someone turned it off elsewhere is worse than one more request
 * a minute. Decision: not while busy, to keep the ESP32's lane free for the job polls.
 */
export const SETTINGS_REFRESH_MS = 60_000;

export interface Identity {
  type: string | null;
  power: number | null;
  powerInfoType: number | null;
  version: string | null;
  sn: string | null;
  mac: string | null;
  name: string | null;
}

export interface UploadState {
  name: string;
  path: string;
  loaded: number;
  total: number;
  phase: 'uploading' | 'verifying' | 'done' | 'failed';
  message: string | null;
}

export interface ConsoleEntry {
  at: number;
  code: string;
  ok: boolean;
  reply: string;
}

/** Vendor detail of one laser, beside the normalized snapshot. */
export interface XtoolDetail {
  model: { family: 'unknown' | 'd-series' | 'unsupported'; answered: string[] };
  identity: Identity;
  machine: MachineState;
  /** Where the current state came from. */
  source: 'poll' | 'socket' | 'command' | null;
  lastFrame: { raw: string; at: number } | null;
  working: WorkingSta | null;
  progress: Progress | null;
  periphery: PeripheryStatus | null;
  offset: { x: number; y: number } | null;
  dotMode: number | null;
  files: { dir: string; entries: string[]; at: number } | null;
  filesError: string | null;
  upload: UploadState | null;
  upgrade: UploadState | null;
  console: ConsoleEntry[];
  socketOpen: boolean;
  /** The name of the job we uploaded or started, when we know it. */
  jobName: string | null;
  /** A plain sentence for the operator after an upload ("press the button on the machine"). */
  notice: string | null;
}

const EMPTY_IDENTITY: Identity = {
  type: null,
  power: null,
  powerInfoType: null,
  version: null,
  sn: null,
  mac: null,
  name: null,
};

export function initialDetail(): XtoolDetail {
  return {
    model: { family: 'unknown', answered: [] },
    identity: EMPTY_IDENTITY,
    machine: INITIAL_STATE,
    source: null,
    lastFrame: null,
    working: null,
    progress: null,
    periphery: null,
    offset: null,
    dotMode: null,
    files: null,
    filesError: null,
    upload: null,
    upgrade: null,
    console: [],
    socketOpen: false,
    jobName: null,
    notice: null,
  };
}

type Sensors = 'limit' | 'tilt' | 'moving';
const SWITCH: Record<Sensors, { action: SwitchAction; words: string; risk: string }> = {
  limit: {
    action: 'setLimitStopSwitch',
    words: 'limit stop',
    risk: 'the laser head can drive into the frame ends without stopping the job',
  },
  tilt: {
    action: 'setTiltStopSwitch',
    words: 'tilt stop',
    risk: 'the laser keeps firing when the machine tips over or is lifted',
  },
  moving: {
    action: 'setMovingStopSwitch',
    words: 'movement stop',
    risk: 'the laser keeps firing when the machine is bumped or moved',
  },
};

export interface UploadArgs {
  file: Blob;
  /** Shown to the operator ("coaster.gcode"). */
  name: string;
  target: UploadTarget;
}

function parentDir(path: string): string {
  const i = path.lastIndexOf('/');
  return i <= 0 ? '/' : path.slice(0, i);
}

/**
 * The job name to show after a state change. The laser never names its job: a name we learnt (our
 * upload, our remote start) is forgotten once the laser is idle, so the next job started from the
 * vendor app is not shown under the old name. A job loaded by software is the uploaded
 * /tmp.gcode (document: "Type 1 = /tmp.gcode"), so that is its name when we know no better.
 */
function jobNameAfter(name: string | null, m: MachineState): string | null {
  if (m.state === 'idle' || m.state === 'alarm' || m.state === 'error') return null;
  if (name === null && m.state === 'job-loaded') return 'tmp.gcode';
  return name;
}

function checkByte(value: number, what: string): void {
  if (!Number.isInteger(value) || value < 0 || value > 255) {
    throw new LinkError('vendor', `${what} must be a whole number from 0 to 255 (got ${value})`);
  }
}

/**
 * One xTool D-series laser. On connect: /ping, identity, get_working_sta, /progress,
 * /peripherystatus; then WebSocket frames drive the state and a poll of get_working_sta +
 * /progress runs every 3 s while busy, every 10 s when idle (slower while the page is hidden),
 * never two requests at once (the client's lane). No frame and a failed poll means offline.
 */
export class XtoolSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly client: XtoolClient;
  readonly detail: StoreApi<XtoolDetail> = createStore<XtoolDetail>(() => initialDetail());
  readonly poller: Poller;
  private readonly link: LinkTracker;
  private socket: SocketLink | null = null;
  private connected = false;
  private retryDelay = 1000;
  private pollStartedAt = 0;
  private settingsAt = 0;
  private stopped = true;

  constructor(readonly ctx: SessionContext) {
    this.machine = ctx.machine;
    this.client = new XtoolClient(ctx.machine.id);
    this.link = new LinkTracker(ctx);
    this.poller = new Poller({
      run: () => (this.connected ? this.poll() : this.connect()),
      intervalMs: () => (isBusy(this.detail.getState().machine.state) ? POLL_BUSY_MS : POLL_IDLE_MS),
      visibility: ctx.visibility,
      onError: (e) => this.pollFailed(e),
      retryDelayMs: () => this.retryDelay,
    });
  }

  start(): void {
    if (!this.stopped) return;
    this.stopped = false;
    this.poller.start();
  }

  stop(): void {
    this.stopped = true;
    this.poller.stop();
    this.socket?.close();
    this.socket = null;
  }

  private set(patch: Partial<XtoolDetail> | ((s: XtoolDetail) => Partial<XtoolDetail>)): void {
    this.detail.setState(patch);
  }

  // --- connecting and polling ---------------------------------------------------------------

  private async connect(): Promise<void> {
    await this.client.ping().catch((e: unknown) => {
      // Another xTool family may not know /ping at all; it answered, so identify it.
      if (e instanceof LinkError && (e.kind === 'http' || e.kind === 'vendor' || e.kind === 'protocol'))
        return;
      throw e;
    });
    if (!(await this.identify())) return;
    const optional = <T>(what: string, p: Promise<T>): Promise<T | null> =>
      p.catch((e: unknown) => {
        if (e instanceof LinkError && (e.kind === 'vendor' || e.kind === 'protocol')) {
          this.ctx.log.warn('protocol', `${what}: ${e.message}`);
          return null;
        }
        throw e;
      });
    const power = await optional('laser power', this.client.laserPowerType());
    const powerInfo = await optional('laser module', this.client.laserPowerInfo());
    const version = await optional('firmware version', this.client.version());
    const mac = await optional('MAC address', this.client.mac());
    const name = await optional('device name', this.client.deviceName());
    this.set((s) => ({
      identity: {
        ...s.identity,
        power: power?.power ?? powerInfo?.power ?? null,
        powerInfoType: powerInfo?.type ?? null,
        version: version?.version ?? null,
        sn: version?.sn ?? null,
        mac: mac?.mac ?? null,
        name: name?.name ?? null,
      },
    }));
    await this.poll();
    await this.refreshSettings();
    this.connected = true;
    this.link.ok({ identity: this.identityLine() });
    this.openSocket();
    void this.refreshFiles().catch(() => undefined);
  }

  /** Tell the D-series from other xTool families. Returns false (and stops) for other models. */
  private async identify(): Promise<boolean> {
    let type: string | null = null;
    let answered: string | null = null;
    try {
      type = (await this.client.machineType()).type;
    } catch (e) {
      if (!(e instanceof LinkError) || !(e.kind === 'http' || e.kind === 'vendor' || e.kind === 'protocol'))
        throw e;
      answered = `/getmachinetype → ${e.message}`;
    }
    if (type !== null && classifyMachineType(type) === 'd-series') {
      this.set((s) => ({ model: { family: 'd-series', answered: [] }, identity: { ...s.identity, type } }));
      return true;
    }
    // Not a D-series: show what it said (and what /status says, the REST V1 of F1/P2/M1).
    const lines = [type !== null ? `/getmachinetype → type "${type}"` : (answered ?? '')];
    lines.push(await this.client.probe('/status'));
    this.set((s) => ({
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
    return false;
  }

  /** get_working_sta + /progress. */
  private async poll(): Promise<void> {
    this.pollStartedAt = this.ctx.now();
    const working = await this.client.workingSta();
    const progress = await this.client.progress();
    const s = this.detail.getState();
    // A frame that arrived while this poll was in flight is newer than the poll: it wins.
    const frameWins = s.lastFrame !== null && s.lastFrame.at >= this.pollStartedAt;
    const machine = frameWins ? s.machine : applyPoll(s.machine, working.code, progress, s.progress);
    if (working.code === 'unknown') this.ctx.log.warn('protocol', `Unknown working state "${working.raw}"`);
    this.set({
      working,
      progress,
      machine,
      source: frameWins ? s.source : 'poll',
      jobName: jobNameAfter(s.jobName, machine),
    });
    if (this.connected) this.link.ok(this.derived());
    else this.link.patch(this.derived());
    if (this.connected && !isBusy(machine.state) && this.ctx.now() - this.settingsAt >= SETTINGS_REFRESH_MS) {
      await this.refreshSettings();
    }
  }

  private pollFailed(e: unknown): void {
    if (this.stopped) return;
    // A powered-off laser is offline, not an error: with no socket either, the first failure says so.
    const socketUp = this.socket?.open ?? false;
    this.retryDelay = this.link.fail(e, { offlineAfter: socketUp ? 3 : 1 });
    if (this.link.state === 'offline') {
      // Identify again when it comes back: it may have been power-cycled or swapped.
      this.connected = false;
      this.set({ machine: INITIAL_STATE, source: null });
    }
  }

  /** Re-read /peripherystatus, offset and dot mode. */
  async refreshSettings(): Promise<void> {
    this.settingsAt = this.ctx.now();
    const periphery = await this.client.peripheryStatus().catch((e: unknown) => {
      if (e instanceof LinkError && e.kind === 'vendor') return null;
      throw e;
    });
    const offset = await this.client.offset().catch(() => null);
    const dot = await this.client.dotMode().catch(() => null);
    this.set({
      periphery,
      offset: offset ? { x: offset.x, y: offset.y } : null,
      dotMode: dot?.dotMode ?? null,
    });
  }

  async refreshFiles(dir = '/'): Promise<void> {
    try {
      const list = await this.client.list(dir);
      this.set({ files: { dir, entries: list.name, at: this.ctx.now() }, filesError: null });
    } catch (e) {
      this.set({ filesError: describeError(e) });
      throw e;
    }
  }

  // --- the WebSocket ------------------------------------------------------------------------

  private openSocket(): void {
    if (this.socket || this.stopped) return;
    this.socket = new SocketLink({
      url: () => `${machineBase(this.machine.id)}/`,
      onOpen: () => {
        this.set({ socketOpen: true });
        this.ctx.log.info('link', 'status socket open');
      },
      onClose: () => {
        if (this.detail.getState().socketOpen)
          this.ctx.log.warn('link', 'status socket closed; reconnecting');
        this.set({ socketOpen: false });
      },
      onMessage: (data) => this.onFrame(data),
    });
  }

  /** One WebSocket frame. Public for tests that drive the state machine. */
  onFrame(data: string): void {
    const parsed = frameSchema.safeParse(data);
    if (!parsed.success) return;
    const f = parsed.data;
    const at = this.ctx.now();
    if (f.kind === 'unknown') {
      this.ctx.log.warn('controller', `Unknown frame "${f.raw}"`);
      this.set({ lastFrame: { raw: f.raw, at } });
      return;
    }
    const before = this.detail.getState().machine;
    const machine = applyFrame(before, f);
    this.set((s) => ({
      machine,
      lastFrame: { raw: f.raw, at },
      source: 'socket',
      jobName: jobNameAfter(s.jobName, machine),
    }));
    this.ctx.log.add(f.kind === 'sensor' || f.kind === 'error' ? 'error' : 'info', 'controller', f.raw);
    const alarm = alarmForFrame(f, at);
    const alarms = alarm ? raiseAlarm(this.ctx.snapshot.getState().alarms, alarm) : undefined;
    this.link.patch({ ...this.derived(), ...(alarms ? { alarms } : {}), updatedAt: at });
    if (machine.state === 'job-loaded' || machine.state === 'frame-ready') {
      this.set({ notice: 'The laser is waiting: the job starts with the button on the machine.' });
    }
    // Busy-ness changed, or the laser is back while we thought it gone: poll now.
    if (isBusy(before.state) !== isBusy(machine.state) || this.link.state !== 'online') this.poller.kick();
  }

  // --- the snapshot ---------------------------------------------------------------------------

  private identityLine(): string | null {
    const id = this.detail.getState().identity;
    const parts = [id.type, id.power !== null ? `${id.power} W` : null, id.version].filter((p) => p);
    return parts.length ? parts.join(' · ') : null;
  }

  private derived(): Partial<MachineSnapshot> {
    const s = this.detail.getState();
    return {
      activity: toActivity(s.machine.state),
      activityLabel: stateLabel(s.machine),
      job: jobSummary(s.machine, s.progress, s.jobName),
    };
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
      this.poller.kick();
    }
  }

  // --- commands -----------------------------------------------------------------------------

  private state(): MachineState {
    return this.detail.getState().machine;
  }

  private jobActionAccepted(action: 'pause' | 'resume' | 'stop'): void {
    this.set((s) => ({ machine: applyJobAction(s.machine, action), source: 'command' }));
    this.link.patch(this.derived());
  }

  private async afterCommand(): Promise<void> {
    this.poller.kick();
  }

  readonly pause: CommandDecl = {
    id: 'xtool.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: () =>
      this.state().state === 'running' || this.state().state === 'button' ? true : 'No job is running',
    perform: async (_a, { commandId }) => {
      await this.client.jobAction('pause', commandId);
      this.jobActionAccepted('pause');
      await this.afterCommand();
      return 'job paused';
    },
  };

  readonly resume: CommandDecl = {
    id: 'xtool.resume',
    label: 'Resume',
    hazard: 'job',
    role: 'operator',
    confirm: 'Resume the job? The laser fires again.',
    available: () => (this.state().state === 'paused' ? true : 'The job is not paused'),
    perform: async (_a, { commandId }) => {
      await this.client.jobAction('resume', commandId);
      this.jobActionAccepted('resume');
      await this.afterCommand();
      return 'job resumed';
    },
  };

  readonly stopJob: CommandDecl = {
    id: 'xtool.stop',
    label: 'Stop',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Stop the job? It cannot be resumed; the piece may be spoiled.',
    available: () => {
      const s = this.state().state;
      return isRunningJob(s) || s === 'job-loaded' || s === 'frame-ready' ? true : 'Nothing to stop';
    },
    perform: async (_a, { commandId }) => {
      await this.client.jobAction('stop', commandId);
      this.jobActionAccepted('stop');
      await this.afterCommand();
      return 'job stopped';
    },
  };

  readonly upload: CommandDecl<UploadArgs> = {
    id: 'xtool.upload',
    label: 'Upload',
    hazard: 'job',
    role: 'operator',
    confirm: (a) =>
      a.target.kind === 'path'
        ? `Copy ${a.name} to ${a.target.filename} on the SD card?`
        : `Upload ${a.name} as the ${a.target.kind === 'frame' ? 'framing file' : 'job'}? The laser then waits: it starts with the button on the machine.`,
    available: () => {
      const d = this.detail.getState();
      if (isRunningJob(d.machine.state)) return 'The laser is busy with a job';
      if (d.periphery?.sdCard === false) return 'No SD card in the laser';
      return true;
    },
    perform: (a, { commandId }) => this.doUpload(a, commandId),
  };

  private async doUpload(a: UploadArgs, commandId: string): Promise<string> {
    const path = uploadPath(a.target);
    const set = (u: Partial<UploadState>) =>
      this.set((s) => ({
        upload: {
          ...(s.upload ?? { name: a.name, path, loaded: 0, total: a.file.size }),
          ...u,
        } as UploadState,
      }));
    this.set({
      upload: { name: a.name, path, loaded: 0, total: a.file.size, phase: 'uploading', message: null },
      notice: null,
    });
    const dir = parentDir(path);
    const base = path.slice(path.lastIndexOf('/') + 1);
    const has = (names: string[]) =>
      names.some((n) => n === path || n === base || (n.endsWith(`/${base}`) && parentDir(n) === dir));
    try {
      // The firmware answers "ok" even when the upload failed: believe only what the laser shows
      // afterwards. /list has names only, so note whether a file of that name was there before.
      const st = this.state().state;
      const wasLoaded = st === 'job-loaded' || st === 'frame-ready';
      const before = await this.client.list(dir).then(
        (l) => has(l.name),
        () => false,
      );
      await this.client.upload(a.file, a.target, commandId, (p) => set({ loaded: p.loaded, total: p.total }));
      set({ phase: 'verifying', loaded: a.file.size });
      const list = await this.client.list(dir);
      if (!has(list.name)) {
        throw new LinkError(
          'vendor',
          `The laser answered "ok" but ${path} is not on the SD card: the upload failed.`,
        );
      }
      let caveat = '';
      if (before && a.target.kind !== 'path') {
        // A job or framing upload loads the file: the laser reports "2" (loaded). Still idle means
        // the old file is on the card and the new one never arrived.
        const w = await this.client.workingSta();
        if (wasLoaded) {
          caveat = ` A file was already loaded before; the laser cannot show that the new one replaced it.`;
        } else if (w.code === 'idle') {
          throw new LinkError(
            'vendor',
            `The laser answered "ok" but did not load ${path} (it is idle; the file on the card is the old one): the upload failed.`,
          );
        }
      } else if (before) {
        caveat = ` A file of that name was there before; the SD card listing cannot prove the new one replaced it.`;
      }
      this.set({ files: { dir, entries: list.name, at: this.ctx.now() }, filesError: null });
      const armed = a.target.kind !== 'path';
      const message = armed
        ? `${a.name} is on the laser. The ${a.target.kind === 'frame' ? 'framing' : 'job'} starts with the button on the machine.${caveat}`
        : `${a.name} copied to ${path}.${caveat}`;
      set({ phase: 'done', message });
      if (armed) {
        this.set({
          jobName: a.target.kind === 'job' ? a.name : this.detail.getState().jobName,
          notice: message,
        });
        this.link.patch(this.derived());
      }
      await this.afterCommand();
      return message;
    } catch (e) {
      set({ phase: 'failed', message: describeError(e) });
      throw e;
    }
  }

  readonly deleteFile: CommandDecl<{ path: string }> = {
    id: 'xtool.delete',
    label: 'Delete file',
    hazard: 'adjust',
    role: 'supervisor',
    confirm: (a) => `Delete ${a.path} from the laser's SD card? This cannot be undone.`,
    perform: async (a, { commandId }) => {
      await this.client.deleteFile(a.path, commandId);
      await this.refreshFiles(this.detail.getState().files?.dir ?? '/').catch(() => undefined);
      return `deleted ${a.path}`;
    },
  };

  readonly runFile: CommandDecl<{ path: string }> = {
    id: 'xtool.run-file',
    label: 'Run file now (remote start)',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm: (a) =>
      `Run ${a.path} now? This FIRES THE LASER immediately, without anyone at the machine pressing its button. ` +
      'Send it only if someone is at the laser and watching it.',
    available: () => {
      const s = this.state().state;
      return s === 'idle' || s === 'job-loaded' || s === 'frame-ready' ? true : 'The laser is busy';
    },
    perform: async (a, { commandId }) => {
      await this.client.runFile(a.path, commandId);
      this.set({ jobName: a.path.slice(a.path.lastIndexOf('/') + 1), notice: null });
      this.link.patch(this.derived());
      await this.afterCommand();
      return `started ${a.path}`;
    },
  };

  readonly gcode: CommandDecl<{ code: string }> = {
    id: 'xtool.gcode',
    label: 'Send G-code',
    hazard: 'motion',
    role: 'supervisor',
    // Decision: the console is a supervisor tool used line by line; no confirmation per line.
    confirm: false,
    perform: async (a, { commandId }) => {
      const code = a.code.trim();
      if (!code) throw new LinkError('vendor', 'Nothing to send');
      const entry = (ok: boolean, reply: string) =>
        this.set((s) => ({ console: [...s.console, { at: this.ctx.now(), code, ok, reply }].slice(-200) }));
      try {
        const r = await this.client.gcode(code, commandId);
        entry(true, r.result);
        this.ctx.log.info('console', `> ${code.replace(/\n/g, ' | ')} → ${r.result}`);
        return r.result;
      } catch (e) {
        entry(false, describeError(e));
        throw e;
      }
    },
  };

  readonly setName: CommandDecl<{ name: string }> = {
    id: 'xtool.set-name',
    label: 'Rename the laser',
    hazard: 'adjust',
    role: 'supervisor',
    perform: async (a, { commandId }) => {
      const name = a.name.trim();
      if (!name) throw new LinkError('vendor', 'The name cannot be empty');
      await this.client.setDeviceName(name, commandId);
      const r = await this.client.deviceName();
      this.set((s) => ({ identity: { ...s.identity, name: r.name } }));
      return `renamed to ${r.name}`;
    },
  };

  private switchCommand(sensor: Sensors, on: boolean): CommandDecl {
    const sw = SWITCH[sensor];
    return {
      id: `xtool.${sensor}-stop-${on ? 'on' : 'off'}`,
      label: `Turn the ${sw.words} ${on ? 'on' : 'off'}`,
      hazard: on ? 'adjust' : 'dangerous',
      role: 'supervisor',
      confirm: on
        ? false
        : `Turn the ${sw.words} OFF? Without it ${sw.risk}. Only do this for a reason, and turn it back on afterwards.`,
      perform: async (_a, { commandId }) => {
        await this.client.setSystem(sw.action, on ? 1 : 0, commandId);
        await this.refreshSettings();
        return `${sw.words} ${on ? 'on' : 'off'}`;
      },
    };
  }

  readonly limitStopOn = this.switchCommand('limit', true);
  readonly limitStopOff = this.switchCommand('limit', false);
  readonly tiltStopOn = this.switchCommand('tilt', true);
  readonly tiltStopOff = this.switchCommand('tilt', false);
  readonly movingStopOn = this.switchCommand('moving', true);
  readonly movingStopOff = this.switchCommand('moving', false);

  private byteCommand(
    id: string,
    label: string,
    action: 'setTiltCheckThreshold' | 'setMovingCheckThreshold' | 'setFlameAlarmMode',
  ): CommandDecl<{ value: number }> {
    return {
      id,
      label,
      hazard: 'adjust',
      role: 'supervisor',
      perform: async (a, { commandId }) => {
        checkByte(a.value, label);
        await this.client.setSystem(action, a.value, commandId);
        await this.refreshSettings();
        return `${label}: ${a.value}`;
      },
    };
  }

  readonly tiltThreshold = this.byteCommand(
    'xtool.tilt-threshold',
    'Tilt threshold',
    'setTiltCheckThreshold',
  );
  readonly movingThreshold = this.byteCommand(
    'xtool.moving-threshold',
    'Movement threshold',
    'setMovingCheckThreshold',
  );
  readonly flameMode = this.byteCommand('xtool.flame-mode', 'Flame alarm mode', 'setFlameAlarmMode');

  readonly flameSensitivity: CommandDecl<{ level: 1 | 2 }> = {
    id: 'xtool.flame-sensitivity',
    label: 'Set the flame sensor sensitivity',
    hazard: 'adjust',
    role: 'supervisor',
    perform: async (a, { commandId }) => {
      await this.client.setSystem('setFlameAlarmSensitivity', a.level, commandId);
      await this.refreshSettings();
      return `flame sensitivity ${flameSensitivityWords(a.level)}`;
    },
  };

  readonly flameAlarmOff: CommandDecl = {
    id: 'xtool.flame-alarm-off',
    label: 'Turn the flame alarm off',
    hazard: 'dangerous',
    role: 'supervisor',
    confirm:
      'Turn the flame alarm OFF? The laser will keep firing if the work piece catches fire. ' +
      'Never leave the laser unattended with the flame alarm off.',
    perform: async (_a, { commandId }) => {
      await this.client.setSystem('setFlameAlarmSensitivity', 3, commandId);
      await this.refreshSettings();
      return 'flame alarm off';
    },
  };

  readonly upgrade: CommandDecl<{ file: Blob; name: string }> = {
    id: 'xtool.upgrade',
    label: 'Upgrade firmware',
    hazard: 'dangerous',
    role: 'supervisor',
    confirmTwice: true,
    confirm: (a) =>
      `Flash ${a.name} (${a.file.size} bytes) onto the laser? It runs firmware ${this.detail.getState().identity.version ?? '(unknown)'} now. ` +
      'A wrong or interrupted file can leave the laser unusable.',
    available: () => (this.state().state === 'idle' ? true : 'Only when the laser is idle'),
    perform: async (a, { commandId }) => {
      const path = '/upgrade';
      this.set({
        upgrade: { name: a.name, path, loaded: 0, total: a.file.size, phase: 'uploading', message: null },
      });
      const upd = (u: Partial<UploadState>) =>
        this.set((s) => (s.upgrade ? { upgrade: { ...s.upgrade, ...u } } : {}));
      try {
        const r = await this.client.upgrade(a.file, a.name, commandId, (p) =>
          upd({ loaded: p.loaded, total: p.total }),
        );
        if (r !== 'OK') throw new LinkError('vendor', 'The laser refused the firmware (it answered "FAIL")');
        upd({ phase: 'done', message: 'Firmware accepted. The laser restarts; it is offline for a moment.' });
        return 'firmware accepted';
      } catch (e) {
        upd({ phase: 'failed', message: describeError(e) });
        throw e;
      }
    },
  };

  /** Every declared command, by id. */
  get commands(): Readonly<Record<string, CommandDecl<never>>> {
    const list: Array<CommandDecl<never>> = [
      this.pause,
      this.resume,
      this.stopJob,
      this.upload,
      this.deleteFile,
      this.runFile,
      this.gcode,
      this.setName,
      this.limitStopOn,
      this.limitStopOff,
      this.tiltStopOn,
      this.tiltStopOff,
      this.movingStopOn,
      this.movingStopOff,
      this.tiltThreshold,
      this.movingThreshold,
      this.flameMode,
      this.flameSensitivity,
      this.flameAlarmOff,
      this.upgrade,
    ];
    return Object.fromEntries(list.map((c) => [c.id, c]));
  }
}
