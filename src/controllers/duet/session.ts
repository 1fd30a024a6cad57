import { createStore, type StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../../fleet/contract';
import { describeError, LinkError, protocolError } from '../../fleet/errors';
import type { UploadProgress } from '../../fleet/http';
import { backoffDelay, SocketLink } from '../../fleet/link';
import type { MachineInfo, MachineSnapshot } from '../../fleet/types';
import { JOBS_DIR } from './access';
import { baseName, DuetClient, isAuthError, joinPath, quoteGcode } from './client';
import { applyPatch, isObject, takeFullModel, type Json, type JsonObject } from './patch';
import { isPrinting, snapshotOf } from './snapshot';
import {
  messageLevel,
  messageSchema,
  objectModelSchema,
  parseHeightMap,
  type DirEntry,
  type HeightMap,
  type MessageBox,
  type ObjectModel,
  type ParsedFileInfo,
} from './wire';

/**
 * One Duet (DSF) machine: `GET /machine/connect` (through the gateway: no key, the gateway holds
 * the DSF session; a key only where msw answers), then `WS /machine` for the
 * object model (full model, then patches, `OK\n` after each), `PING\n` after 2 s of silence, and
 * a reconnect when no `PONG\n` comes within 4 s more. Session problems (401/403) reconnect once
 * silently, then show "needs login". Close codes 1001/1011 mean the DSF service is down.
 *
 * The console history is the machine's log (ctx.log), which outlives sockets and reconnects.
 */

export const PING_AFTER_MS = 2000;
export const DEAD_AFTER_MS = 4000;
export const NOOP_EVERY_MS = 4000;
export const HISTORY_POINTS = 900;
/** While the socket cannot be opened, the object model is polled this often (`GET /machine/model`). */
export const POLL_EVERY_MS = 2000;
/** Polling starts only when the socket has been down this long (a quick reconnect needs none). */
export const POLL_AFTER_MS = 5000;

export interface UploadState {
  id: number;
  name: string;
  path: string;
  loaded: number;
  total: number;
  status: 'uploading' | 'done' | 'failed' | 'cancelled';
  error: string | null;
}

export interface DuetState {
  model: ObjectModel | null;
  /** Temperature history, one series per heater index: [ms, °C]. */
  history: Record<number, Array<readonly [number, number]>>;
  /** Codes typed into the console, newest last. */
  codeHistory: string[];
  needsPassword: boolean;
  files: { dir: string; entries: DirEntry[]; loading: boolean; error: string | null };
  fileInfo: Record<string, ParsedFileInfo | { error: string }>;
  uploads: UploadState[];
  heightMap: { path: string | null; map: HeightMap | null; loading: boolean; error: string | null };
  /** Message box seqs the user closed locally (mode 0 has no button to answer). */
  dismissedBoxes: number[];
  /** Where the model comes from: the socket, or polling while the socket cannot be opened. */
  transport: 'socket' | 'polling' | null;
  /** Why the socket is down (shown while polling). */
  socketProblem: string | null;
}

export interface CodeArgs {
  code: string;
  async?: boolean;
}

export class DuetSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly client: DuetClient;
  readonly link: LinkTracker;
  readonly store: StoreApi<DuetState>;
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  readonly cmd: ReturnType<DuetSession['declare']>;

  private socket: SocketLink | null = null;
  private raw: JsonObject | null = null;
  private gotFirst = false;
  private stopped = true;
  private retryTimer: ReturnType<typeof setTimeout> | null = null;
  private watchdog: ReturnType<typeof setInterval> | null = null;
  private lastFrameAt = 0;
  private pingSentAt: number | null = null;
  private lastNoopAt = 0;
  private authRetried = false;
  private password: string | undefined;
  private connecting: Promise<boolean> | null = null;
  private alarmSince = new Map<string, number>();
  private lastHistoryAt = 0;
  private uploadSeq = 0;
  private uploadAborts = new Map<number, AbortController>();
  private generation = 0;
  /** Socket failures in a row (its own backoff: polling keeps the link itself online). */
  private socketFailures = 0;
  private socketDownSince = 0;
  private lastPollAt = 0;
  private lastPollOkAt = 0;
  private pollInFlight = false;
  /** Messages already logged from a polled model (a polled model may repeat them). */
  private polledMessages = new Set<string>();

  constructor(readonly ctx: SessionContext) {
    this.machine = ctx.machine;
    this.client = new DuetClient(ctx.machine.id);
    this.link = new LinkTracker(ctx);
    this.store = createStore<DuetState>(() => ({
      model: null,
      history: {},
      codeHistory: [],
      needsPassword: false,
      files: { dir: '0:/gcodes', entries: [], loading: false, error: null },
      fileInfo: {},
      uploads: [],
      heightMap: { path: null, map: null, loading: false, error: null },
      dismissedBoxes: [],
      transport: null,
      socketProblem: null,
    }));
    this.cmd = this.declare();
    // By id ("duet.pause"), as the contract wants.
    this.commands = Object.fromEntries(
      Object.values(this.cmd).map((c) => [c.id, c as unknown as CommandDecl<never>]),
    );
  }

  // ------------------------------------------------------------------ lifecycle

  start(): void {
    if (!this.stopped) return;
    this.stopped = false;
    this.watchdog = setInterval(() => this.watch(), 500);
    void this.connect();
  }

  stop(): void {
    this.stopped = true;
    this.generation++;
    if (this.retryTimer) clearTimeout(this.retryTimer);
    this.retryTimer = null;
    if (this.watchdog) clearInterval(this.watchdog);
    this.watchdog = null;
    this.closeSocket();
    for (const a of this.uploadAborts.values()) a.abort();
    if (this.client.connected) void this.client.disconnect().catch(() => undefined);
  }

  /** The login form (needs-login): the password is sent with `GET /machine/connect`. */
  async login(credentials: Record<string, string>): Promise<void> {
    this.password = credentials['password'] ?? '';
    this.authRetried = false;
    this.store.setState({ needsPassword: false });
    const ok = await this.connect();
    if (!ok && this.link.state === 'needs-login') throw new Error('The machine refused the password');
  }

  private closeSocket(): void {
    const s = this.socket;
    this.socket = null;
    s?.close();
    this.gotFirst = false;
    this.pingSentAt = null;
  }

  private scheduleReconnect(delay: number): void {
    if (this.stopped) return;
    if (this.retryTimer) clearTimeout(this.retryTimer);
    this.retryTimer = setTimeout(() => {
      this.retryTimer = null;
      void this.connect();
    }, delay);
  }

  /** Connect: a session key, then the socket. Resolves true when the key was obtained. */
  private connect(): Promise<boolean> {
    if (this.connecting) return this.connecting;
    const gen = ++this.generation;
    this.connecting = (async () => {
      if (this.retryTimer) clearTimeout(this.retryTimer);
      this.retryTimer = null;
      this.closeSocket();
      try {
        await this.client.connect(this.password);
      } catch (e) {
        if (gen !== this.generation || this.stopped) return false;
        if (isAuthError(e)) {
          this.needsLogin(e);
          return false;
        }
        this.scheduleReconnect(this.link.fail(e));
        return false;
      }
      if (gen !== this.generation || this.stopped) return false;
      this.openSocket(gen);
      return true;
    })().finally(() => {
      this.connecting = null;
    });
    return this.connecting;
  }

  private needsLogin(e: unknown): void {
    this.closeSocket();
    const err = new LinkError('http', `Needs login: ${describeError(e)}`, { status: 403 });
    this.link.fail(err, { needsLogin: true });
    this.store.setState({ needsPassword: true });
  }

  /** A 401/403 from a request: reconnect once silently, then "needs login". */
  private authFailure(e: unknown): void {
    if (this.stopped) return;
    if (!this.authRetried) {
      this.authRetried = true;
      this.client.forget(); // known bad
      this.ctx.log.add('debug', 'link', 'Session expired: reconnecting');
      void this.connect();
      return;
    }
    this.needsLogin(e);
  }

  private openSocket(gen: number): void {
    this.lastFrameAt = this.ctx.now();
    this.pingSentAt = null;
    this.gotFirst = false;
    const socket = new SocketLink({
      url: () => this.client.socketUrl(),
      autoConnect: false,
      onOpen: () => {
        this.lastFrameAt = this.ctx.now();
      },
      onMessage: (d) => {
        if (this.socket === socket) this.onFrame(d);
      },
      onClose: (code, reason) => {
        if (this.socket === socket && gen === this.generation) this.onSocketClose(code, reason);
        return false; // we reconnect ourselves (a fresh session key first)
      },
    });
    this.socket = socket;
    socket.connect();
  }

  private onSocketClose(code: number, reason: string): void {
    this.socket = null;
    const hadModel = this.gotFirst;
    this.gotFirst = false;
    if (this.stopped) return;
    if (code === 1008 || code === 4403) {
      // DSF refuses the upgrade with 403 when the key is bad.
      this.authFailure(new LinkError('http', `socket refused (${reason || code})`, { status: 403 }));
      return;
    }
    const err: LinkError =
      code === 1001 || code === 1011
        ? new LinkError(
            'vendor',
            `The Duet service (DSF) is down: socket closed with ${code}${reason ? ` (${reason})` : ''}`,
          )
        : new LinkError(
            'network',
            `Socket closed (${code}${reason ? `: ${reason}` : ''})${hadModel ? '' : ' before the object model arrived'}`,
          );
    this.socketFailed(err);
  }

  /**
   * The socket failed. While polling `GET /machine/model` works the machine stays online (the
   * data is fresh, only slower) and the socket is retried on its own backoff; otherwise the link
   * is down as usual.
   */
  private socketFailed(err: LinkError): void {
    if (this.socketFailures === 0) this.socketDownSince = this.ctx.now();
    this.socketFailures++;
    this.store.setState({ socketProblem: err.message });
    if (this.pollingHealthy()) {
      this.scheduleReconnect(backoffDelay(this.socketFailures - 1));
      return;
    }
    this.scheduleReconnect(this.link.fail(err));
  }

  private pollingHealthy(): boolean {
    return this.lastPollOkAt > 0 && this.ctx.now() - this.lastPollOkAt < POLL_EVERY_MS * 3;
  }

  /**
   * Fallback while the socket cannot be opened (a proxy without WebSocket, a socket refused):
   * the full object model by HTTP every POLL_EVERY_MS. It also keeps the session alive. Not a
   * command: a read, never more than one in flight, discarded once the socket delivers again.
   */
  private async poll(): Promise<void> {
    this.pollInFlight = true;
    this.lastPollAt = this.ctx.now();
    try {
      const raw = await this.client.modelRaw();
      if (this.stopped || this.gotFirst) return;
      const r = takeFullModel(raw as JsonObject);
      this.raw = r.model;
      const seen = new Set<string>();
      for (const m of r.messages) {
        const k = JSON.stringify(m);
        seen.add(k);
        if (!this.polledMessages.has(k)) this.logMessage(m);
      }
      this.polledMessages = seen;
      this.lastPollOkAt = this.ctx.now();
      if (this.store.getState().transport !== 'polling') {
        this.ctx.log.add('warning', 'link', 'Live updates unavailable: polling GET /machine/model');
        this.store.setState({ transport: 'polling' });
      }
      this.acceptModel();
    } catch (e) {
      if (isAuthError(e)) this.client.forget(); // the next reconnect gets a new session
    } finally {
      this.pollInFlight = false;
    }
  }

  /** Every 500 ms: PING after 2 s of silence, reconnect when no answer; noop without socket. */
  private watch(): void {
    if (this.stopped) return;
    const now = this.ctx.now();
    const s = this.socket;
    if (s && s.open && this.gotFirst) {
      if (this.pingSentAt !== null && now - this.pingSentAt >= DEAD_AFTER_MS) {
        this.closeSocket();
        this.socketFailed(new LinkError('timeout', 'No answer to PING: the link is dead'));
        return;
      }
      if (this.pingSentAt === null && now - this.lastFrameAt >= PING_AFTER_MS) {
        this.pingSentAt = now;
        s.send('PING\n');
      }
      return;
    }
    // A socket that does not open at all counts as dead too.
    if (s && !this.gotFirst && now - this.lastFrameAt >= PING_AFTER_MS + DEAD_AFTER_MS) {
      this.closeSocket();
      this.socketFailed(new LinkError('timeout', 'The object model did not arrive'));
      return;
    }
    // Without a live socket (after it failed), poll the object model so the page keeps its data.
    if (
      this.socketFailures > 0 &&
      now - this.socketDownSince >= POLL_AFTER_MS &&
      !this.gotFirst &&
      this.client.connected &&
      this.link.state !== 'needs-login' &&
      !this.pollInFlight &&
      now - this.lastPollAt >= POLL_EVERY_MS
    ) {
      this.lastNoopAt = now; // the poll keeps the session alive too
      void this.poll();
      return;
    }
    // Without a socket, keep the session alive (uploads, file operations) with noop.
    if (
      !s &&
      this.client.connected &&
      this.link.state !== 'needs-login' &&
      now - this.lastNoopAt >= NOOP_EVERY_MS
    ) {
      this.lastNoopAt = now;
      this.client.noop().catch((e: unknown) => {
        if (isAuthError(e)) this.client.forget();
      });
    }
  }

  private onFrame(data: string): void {
    const now = this.ctx.now();
    this.lastFrameAt = now;
    this.pingSentAt = null;
    const text = data.trim();
    if (text === 'PONG') return;
    let parsed: unknown;
    try {
      parsed = JSON.parse(text);
    } catch {
      this.link.fail(
        new LinkError('protocol', `WS /machine: a frame that is not JSON (${text.slice(0, 60)})`, {
          path: '(root)',
        }),
      );
      this.socket?.send('OK\n');
      return;
    }
    if (!isObject(parsed as Json)) {
      this.link.fail(
        new LinkError('protocol', 'WS /machine: a frame that is not an object', { path: '(root)' }),
      );
      this.socket?.send('OK\n');
      return;
    }
    const frame = parsed as JsonObject;
    if (!this.gotFirst) {
      // The socket is live again: polling ends.
      this.socketFailures = 0;
      this.lastPollOkAt = 0;
      this.polledMessages.clear();
      this.store.setState({ transport: 'socket', socketProblem: null });
    }
    const r = this.gotFirst && this.raw ? applyPatch(this.raw, frame) : takeFullModel(frame);
    this.gotFirst = true;
    this.raw = r.model;
    for (const m of r.messages) this.logMessage(m);
    this.acceptModel();
    // Acknowledge: the server sends nothing more until it has our OK.
    this.socket?.send('OK\n');
  }

  private logMessage(m: Json): void {
    const p = messageSchema.safeParse(m);
    if (!p.success) return;
    const at = p.data.time ? Date.parse(p.data.time) : NaN;
    this.ctx.log.add(
      messageLevel(p.data.type),
      'controller',
      p.data.content,
      Number.isNaN(at) ? undefined : at,
    );
  }

  private acceptModel(): void {
    const p = objectModelSchema.safeParse(this.raw);
    if (!p.success) {
      this.link.fail(protocolError('WS /machine (object model)', p.error));
      return;
    }
    const m = p.data;
    const now = this.ctx.now();
    this.authRetried = false;
    const since = (id: string): number => {
      const t = this.alarmSince.get(id);
      if (t !== undefined) return t;
      this.alarmSince.set(id, now);
      return now;
    };
    const snap = snapshotOf(m, since);
    const live = new Set((snap.alarms ?? []).map((a) => a.id));
    for (const id of [...this.alarmSince.keys()]) if (!live.has(id)) this.alarmSince.delete(id);
    this.link.ok(snap as Partial<MachineSnapshot>);
    const patch: Partial<DuetState> = { model: m, needsPassword: false };
    if (now - this.lastHistoryAt >= 1000) {
      this.lastHistoryAt = now;
      const history = { ...this.store.getState().history };
      m.heat.heaters.forEach((h, i) => {
        if (!h || h.current <= -273) return;
        const prev = history[i] ?? [];
        const next =
          prev.length >= HISTORY_POINTS ? prev.slice(prev.length - HISTORY_POINTS + 1) : prev.slice();
        next.push([now, h.current] as const);
        history[i] = next;
      });
      patch.history = history;
    }
    this.store.setState(patch);
    const hm = m.move.compensation?.file ?? null;
    if (hm !== this.store.getState().heightMap.path && this.store.getState().heightMap.path !== null) {
      this.store.setState((s) => ({ heightMap: { ...s.heightMap, path: hm, map: null } }));
    }
  }

  // ------------------------------------------------------------------ requests

  /** A read: on 401/403 reconnect (once) and try once more. */
  private async read<T>(fn: () => Promise<T>): Promise<T> {
    try {
      return await fn();
    } catch (e) {
      if (!isAuthError(e) || this.authRetried) throw e;
      this.authRetried = true;
      const ok = await this.connect();
      if (!ok) throw e;
      return fn();
    }
  }

  /**
   * A command: sent once. A 401/403 is never resent (a command is never replayed): the session
   * reconnects in the background and the user is told to try again.
   */
  private async send<T>(fn: () => Promise<T>): Promise<T> {
    try {
      return await fn();
    } catch (e) {
      if (isAuthError(e)) {
        this.authFailure(e);
        throw new Error(
          'The session had expired, so the command was NOT carried out. Reconnecting — try again.',
        );
      }
      throw e;
    }
  }

  /** Send G-code; the reply goes to the console log. An "Error:" reply fails the command. */
  private async code(
    code: string,
    commandId: string,
    opts: { async?: boolean; logCode?: boolean } = {},
  ): Promise<string> {
    if (opts.logCode !== false) this.ctx.log.add('info', 'console', `> ${code.replace(/\n/g, ' | ')}`);
    const reply = await this.send(() => this.client.code(code, { commandId, async: opts.async }));
    this.logReply(reply);
    const err = reply
      .split('\n')
      .map((l) => l.trim())
      .find((l) => l.startsWith('Error:'));
    if (err) throw new Error(err);
    return reply.trim() || 'ok';
  }

  private logReply(reply: string): void {
    const t = reply.trim();
    if (!t) return;
    for (const line of t.split('\n')) {
      const level = line.startsWith('Error:') ? 'error' : line.startsWith('Warning:') ? 'warning' : 'info';
      this.ctx.log.add(level, 'console', line);
    }
  }

  // ------------------------------------------------------------------ commands

  private declare() {
    const status = (s: MachineSnapshot) => s.activity;
    const model = () => this.store.getState().model;
    const printing = () => {
      const m = model();
      return m ? isPrinting(m.state.status) : false;
    };
    const start: CommandDecl<{ path: string }> = {
      id: 'duet.start',
      label: 'Start print',
      hazard: 'job',
      role: 'operator',
      confirm: (a) =>
        `Start printing ${baseName(a.path)}? The heaters will switch on and the machine will move.`,
      available: (s) => (status(s) === 'idle' && !printing() ? true : 'The machine is not idle'),
      perform: (a, c) => this.code(`M32 ${quoteGcode(a.path)}`, c.commandId),
    };
    const simulate: CommandDecl<{ path: string }> = {
      id: 'duet.simulate',
      label: 'Simulate',
      hazard: 'job',
      role: 'operator',
      confirm: (a) =>
        `Simulate ${baseName(a.path)}? Nothing moves; the machine is busy until the simulation ends.`,
      available: (s) => (status(s) === 'idle' && !printing() ? true : 'The machine is not idle'),
      perform: (a, c) => this.code(`M37 P${quoteGcode(a.path)}`, c.commandId),
    };
    const pause: CommandDecl<void> = {
      id: 'duet.pause',
      label: 'Pause',
      hazard: 'job',
      role: 'operator',
      confirm: false,
      available: () => {
        const st = model()?.state.status;
        return st === 'processing' || st === 'simulating' ? true : 'Nothing is printing';
      },
      perform: (_a, c) => this.code('M25', c.commandId),
    };
    const resume: CommandDecl<void> = {
      id: 'duet.resume',
      label: 'Resume',
      hazard: 'job',
      role: 'operator',
      confirm: 'Resume the print? The machine will move.',
      available: () => (model()?.state.status === 'paused' ? true : 'Only a paused print can be resumed'),
      perform: (_a, c) => this.code('M24', c.commandId),
    };
    // Cancel only while paused, as Duet Web Control offers it.
    const cancel: CommandDecl<void> = {
      id: 'duet.cancel',
      label: 'Cancel print',
      hazard: 'stop',
      role: 'operator',
      confirm: 'Cancel the print? It cannot be resumed afterwards.',
      available: () =>
        model()?.state.status === 'paused'
          ? true
          : 'Pause the print first: only a paused print can be cancelled',
      perform: (_a, c) => this.code('M0', c.commandId),
    };
    // One tap, no confirmation: M112 then M999 (reset) in one request.
    const estop: CommandDecl<void> = {
      id: 'duet.estop',
      label: 'Emergency stop',
      hazard: 'stop',
      role: 'operator',
      confirm: false,
      perform: async (_a, c) => {
        this.ctx.log.add('warning', 'console', '> M112 | M999 (emergency stop)');
        const reply = await this.client.code('M112\nM999', { commandId: c.commandId, timeoutMs: 10_000 });
        this.logReply(reply);
        return 'emergency stop sent';
      },
    };
    const console: CommandDecl<CodeArgs> = {
      id: 'duet.code',
      label: 'Send G-code',
      hazard: 'motion',
      role: 'supervisor',
      confirm: false,
      perform: async (a, c) => {
        this.store.setState((s) => ({
          codeHistory: [...s.codeHistory.filter((h) => h !== a.code), a.code].slice(-100),
        }));
        this.ctx.log.add('info', 'console', `> ${a.code.replace(/\n/g, ' | ')}`);
        const reply = await this.send(() =>
          this.client.code(a.code, { commandId: c.commandId, async: a.async }),
        );
        this.logReply(reply);
        return reply.trim() || (a.async ? 'sent (async)' : 'ok');
      },
    };
    const answer: CommandDecl<{ box: MessageBox; cancel?: boolean; value?: number | string }> = {
      id: 'duet.messageBox',
      label: 'Answer message',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: (a, c) => this.code(messageBoxReply(a.box, a.cancel ?? false, a.value), c.commandId),
    };
    const heaterReset: CommandDecl<{ heater: number }> = {
      id: 'duet.heaterReset',
      label: 'Reset heater fault',
      hazard: 'dangerous',
      role: 'supervisor',
      confirm: (a) =>
        `Reset the fault of heater ${a.heater}? Find out why it faulted first: the heater can be switched on again afterwards.`,
      perform: (a, c) => this.code(`M562 P${a.heater}`, c.commandId),
    };
    const macro: CommandDecl<{ path: string }> = {
      id: 'duet.macro',
      label: 'Run macro',
      hazard: 'motion',
      role: 'supervisor',
      confirm: (a) => `Run the macro ${baseName(a.path)}? It may move the machine or switch heaters on.`,
      available: () => (printing() ? 'A job is running' : true),
      perform: (a, c) => this.code(`M98 P${quoteGcode(a.path)}`, c.commandId),
    };
    const uploadJob: CommandDecl<{ file: Blob; name: string; dir: string }> = {
      id: 'duet.uploadJob',
      label: 'Upload job file',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: (a, c) => this.upload(a.file, joinPath(a.dir, a.name), c.commandId),
    };
    const upload: CommandDecl<{ file: Blob; name: string; dir: string }> = {
      id: 'duet.upload',
      label: 'Upload file',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: false,
      perform: (a, c) => this.upload(a.file, joinPath(a.dir, a.name), c.commandId),
    };
    const del: CommandDecl<{ path: string; dir: boolean }> = {
      id: 'duet.delete',
      label: 'Delete',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: (a) => (a.dir ? `Delete the folder ${a.path} and everything in it?` : `Delete ${a.path}?`),
      perform: async (a, c) => {
        await this.send(() => this.client.deleteFile(a.path, { recursive: a.dir, commandId: c.commandId }));
        void this.refreshDir();
        return `deleted ${a.path}`;
      },
    };
    const move: CommandDecl<{ from: string; to: string; force?: boolean }> = {
      id: 'duet.move',
      label: 'Rename / move',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: false,
      perform: async (a, c) => {
        await this.send(() => this.client.move(a.from, a.to, { force: a.force, commandId: c.commandId }));
        void this.refreshDir();
        return `moved to ${a.to}`;
      },
    };
    const mkdir: CommandDecl<{ path: string }> = {
      id: 'duet.mkdir',
      label: 'New folder',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: false,
      perform: async (a, c) => {
        await this.send(() => this.client.makeDirectory(a.path, c.commandId));
        void this.refreshDir();
        return `created ${a.path}`;
      },
    };
    const pluginInstall: CommandDecl<{ file: Blob; name: string }> = {
      id: 'duet.pluginInstall',
      label: 'Install plugin',
      hazard: 'dangerous',
      role: 'supervisor',
      confirm: (a) => `Install the plugin ${a.name}? Plugins run code on the machine's computer.`,
      perform: async (a, c) => {
        await this.send(() => this.client.installPlugin(a.file, c.commandId));
        return `installed ${a.name}`;
      },
    };
    const pluginUninstall: CommandDecl<{ id: string }> = {
      id: 'duet.pluginUninstall',
      label: 'Uninstall plugin',
      hazard: 'dangerous',
      role: 'supervisor',
      confirm: (a) => `Uninstall the plugin ${a.id}?`,
      perform: async (a, c) => {
        await this.send(() => this.client.uninstallPlugin(a.id, c.commandId));
        return `uninstalled ${a.id}`;
      },
    };
    const pluginStart: CommandDecl<{ id: string }> = {
      id: 'duet.pluginStart',
      label: 'Start plugin',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: false,
      perform: async (a, c) => {
        await this.send(() => this.client.startPlugin(a.id, c.commandId));
        return `started ${a.id}`;
      },
    };
    const pluginStop: CommandDecl<{ id: string }> = {
      id: 'duet.pluginStop',
      label: 'Stop plugin',
      hazard: 'adjust',
      role: 'supervisor',
      confirm: (a) => `Stop the plugin ${a.id}?`,
      perform: async (a, c) => {
        await this.send(() => this.client.stopPlugin(a.id, c.commandId));
        return `stopped ${a.id}`;
      },
    };
    return {
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
  }

  /** Which upload command applies to a directory (operator only into the jobs folder). */
  uploadCommandFor(dir: string): CommandDecl<{ file: Blob; name: string; dir: string }> {
    const d = dir.endsWith('/') ? dir : `${dir}/`;
    return d.startsWith(JOBS_DIR) ? this.cmd.uploadJob : this.cmd.upload;
  }

  // ------------------------------------------------------------------ files

  private async upload(file: Blob, path: string, commandId: string): Promise<string> {
    const id = ++this.uploadSeq;
    const ctrl = new AbortController();
    this.uploadAborts.set(id, ctrl);
    const name = baseName(path);
    const set = (p: Partial<UploadState>) =>
      this.store.setState((s) => ({ uploads: s.uploads.map((u) => (u.id === id ? { ...u, ...p } : u)) }));
    this.store.setState((s) => ({
      uploads: [
        ...s.uploads.filter((u) => u.status === 'uploading').slice(-20),
        { id, name, path, loaded: 0, total: file.size, status: 'uploading', error: null },
      ],
    }));
    const lastModified = (file as Blob & { lastModified?: number }).lastModified;
    try {
      // Cancel wins at once in the console, whatever the transport does with the abort.
      const aborted = new Promise<never>((_, reject) =>
        ctrl.signal.addEventListener('abort', () => reject(new LinkError('aborted', 'Upload cancelled'))),
      );
      aborted.catch(() => undefined);
      await Promise.race([
        this.send(() =>
          this.client.upload(path, file, {
            timeModified: lastModified ? new Date(lastModified) : new Date(this.ctx.now()),
            onProgress: (p: UploadProgress) => set({ loaded: p.loaded, total: p.total || file.size }),
            signal: ctrl.signal,
            commandId,
          }),
        ),
        aborted,
      ]);
      set({ status: 'done', loaded: file.size });
      void this.refreshDir();
      return `uploaded ${name}`;
    } catch (e) {
      const cancelled = e instanceof LinkError && e.kind === 'aborted';
      set({ status: cancelled ? 'cancelled' : 'failed', error: describeError(e) });
      throw e;
    } finally {
      this.uploadAborts.delete(id);
    }
  }

  cancelUpload(id: number): void {
    this.uploadAborts.get(id)?.abort();
  }

  async loadDir(dir: string): Promise<void> {
    this.store.setState((s) => ({ files: { ...s.files, dir, loading: true, error: null } }));
    try {
      const entries = await this.read(() => this.client.listDirectory(dir));
      if (this.store.getState().files.dir !== dir) return;
      this.store.setState({ files: { dir, entries, loading: false, error: null } });
    } catch (e) {
      if (this.store.getState().files.dir !== dir) return;
      this.store.setState({ files: { dir, entries: [], loading: false, error: describeError(e) } });
    }
  }

  refreshDir(): Promise<void> {
    return this.loadDir(this.store.getState().files.dir);
  }

  async loadFileInfo(path: string): Promise<void> {
    if (this.store.getState().fileInfo[path]) return;
    try {
      const info = await this.read(() => this.client.fileInfo(path, true));
      this.store.setState((s) => ({ fileInfo: { ...s.fileInfo, [path]: info } }));
    } catch (e) {
      this.store.setState((s) => ({ fileInfo: { ...s.fileInfo, [path]: { error: describeError(e) } } }));
    }
  }

  download(path: string): Promise<Blob> {
    return this.read(() => this.client.download(path));
  }

  async loadHeightMap(): Promise<void> {
    const path = this.store.getState().model?.move.compensation?.file ?? '0:/sys/heightmap.csv';
    this.store.setState({ heightMap: { path, map: null, loading: true, error: null } });
    try {
      const text = await this.read(() => this.client.readText(path));
      this.store.setState({ heightMap: { path, map: parseHeightMap(text), loading: false, error: null } });
    } catch (e) {
      this.store.setState({ heightMap: { path, map: null, loading: false, error: describeError(e) } });
    }
  }

  dismissBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: [...s.dismissedBoxes.slice(-20), seq] }));
  }

  /** Show a hidden message box again. */
  reopenBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: s.dismissedBoxes.filter((d) => d !== seq) }));
  }
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
