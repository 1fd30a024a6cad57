import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand } from '../../fleet/commands';
import type { LinkTracker, SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import type { RunToken } from '../../fleet/kernel';
import { DuetPageApi } from './page-api';
import type { Poller, SocketLink } from '../../fleet/link';
import { DuetClient, isAuthError } from './client';
import {
  asLinkFault,
  authRetryDelay,
  isLinkFault,
  Liveness,
  quickBackoff,
  quickRetry,
} from '../../fleet/faults';
import { declareCommands, type DuetCommands } from './commands';
import { ModelIngest } from './ingest';
import type { JsonObject } from './patch';
import { DuetReads, type Reader } from './reads';
import { createDuetStore, type DuetState } from './state';
import {
  AckPacer,
  pollSilentError,
  Resync,
  SocketDown,
  socketCloseError,
  socketDeadError,
} from './socket-rules';
import {
  DEAD_AFTER_MS,
  FIRST_MODEL_MS,
  NOOP_EVERY_MS,
  PASSWORD_REFUSED,
  PING_AFTER_MS,
  POLL_EVERY_MS,
  POLL_SILENT_MS,
  RRF_POLL_MS,
  RRF_TILE_POLL_MS,
} from './timing';
import { DuetUploads } from './uploads';

export { messageBoxReply, validateBoxValue } from './commands';
export {
  DEAD_AFTER_MS,
  FIRST_MODEL_MS,
  NOOP_EVERY_MS,
  PASSWORD_REFUSED,
  PING_AFTER_MS,
  POLL_AFTER_MS,
  POLL_EVERY_MS,
  POLL_SILENT_MS,
  RESYNC_EVERY_MS,
  RRF_POLL_MS,
  RRF_TILE_POLL_MS,
  TILE_ACK_MS,
} from './timing';
export { HISTORY_POINTS, type CodeArgs, type DuetState, type UploadState } from './state';

/**
 * One Duet (DSF) machine on the session kernel: `GET /machine/connect`, then `WS /machine` for the
 * object model (full model, then patches, `OK\n` after each) under a PING heartbeat; the model
 * polled and the session kept alive while the socket is down; a standalone board (`rr_*`) polled.
 * Close codes, re-login, bad data and liveness: README "Decisions where the document is silent".
 * The console history is the machine's log (ctx.log), which outlives sockets and reconnects.
 */
export class DuetSession extends DuetPageApi {
  readonly client: DuetClient;
  readonly store: StoreApi<DuetState>;
  /** On-demand reads (listings, file info, height map) as queries of this machine. */
  readonly reads: DuetReads;
  readonly cmd: DuetCommands;
  readonly commands: Readonly<Record<string, AnyCommand>>;

  private readonly ingest: ModelIngest;
  protected readonly uploads: DuetUploads;
  private readonly socket: { current: () => SocketLink | null };
  /** The `OK` after each frame (paced on a tile). */
  private readonly acks: AckPacer;
  /** `GET /machine/model` while the socket has been down for POLL_AFTER_MS. */
  private readonly modelPoll: Poller;
  /** `GET /machine/noop` while the socket is down (and the model is not polled yet). */
  private readonly noopPoll: Poller;
  /** A standalone board: `rr_model` (live parts, changed parts, the reply) every RRF_POLL_MS. */
  private readonly rrfPoll: Poller;
  /** The current socket delivered its full model (later frames are patches). */
  private gotFirst = false;
  /** Since when the socket does not deliver, and the polled model meanwhile. */
  private readonly down: SocketDown;
  private authRetried = false;
  /** Typed into the login form on this page; undefined: the credentials are the gateway's. */
  private password: string | undefined;
  /** Refusals of the gateway's credentials in a row (the slow retry's backoff). */
  private authRefusals = 0;
  /** When this run started (an outage is measured from the last good data or this). */
  private startedAt = 0;
  private connecting: { run: RunToken; done: Promise<boolean> } | null = null;
  /** While the model is polled, its answers must keep coming (POLL_SILENT_MS). */
  private readonly pollLiveness: Liveness;
  /** The model read again by a new socket after a dropped frame. */
  private readonly resyncs: Resync;

  constructor(ctx: SessionContext) {
    super(ctx);
    this.client = new DuetClient(ctx.machine.id);
    this.store = createDuetStore();
    this.down = new SocketDown(ctx.now);
    this.ingest = new ModelIngest({
      ctx,
      tracker: this.tracker,
      store: this.store,
      accepted: () => {
        this.authRetried = false;
        this.authRefusals = 0;
      },
      resync: () => this.resyncs.request(),
    });
    const read: Reader = (fn, signal) => this.read(fn, signal);
    this.reads = new DuetReads(ctx.queries, this.client, read);
    const send = <T>(fn: () => Promise<T>) => this.send(fn);
    this.uploads = new DuetUploads({
      store: this.store,
      client: this.client,
      now: ctx.now,
      run: () => (this.started ? this.run() : null),
      send,
      filesChanged: (paths) => this.reads.changed(paths),
    });
    const { cmd, all } = declareCommands({
      ctx,
      store: this.store,
      client: this.client,
      send,
      sent: () => this.modelPoll.kick(),
      upload: (file, path, commandId) => this.uploads.upload(file, path, commandId),
      filesChanged: (paths) => this.reads.changed(paths),
    });
    this.cmd = cmd;
    this.commands = all;

    this.socket = this.stream(() => ({
      url: () => this.client.socketUrl(),
      // Opened once a session is there (onStart → connect), reconnected on its own backoff:
      // quick while the outage is young (back within 5 s of the fault ending).
      autoConnect: false,
      backoff: quickBackoff(ctx, () => this.startedAt),
      now: ctx.now,
      onOpen: () => {
        this.gotFirst = false;
      },
      onMessage: (d) => this.onFrame(d),
      onClose: (code, reason) => this.onSocketClose(code, reason),
      heartbeat: {
        silenceMs: PING_AFTER_MS,
        ping: 'PING\n',
        answerMs: DEAD_AFTER_MS,
        firstMessageMs: FIRST_MODEL_MS,
        onDead: (why) => this.onSocketDead(why),
      },
    }));
    this.acks = new AckPacer(
      ctx,
      () => this.socket.current(),
      (fn, ms) => this.later(fn, ms),
    );
    this.resyncs = new Resync({
      now: ctx.now,
      later: (fn, ms) => this.later(fn, ms),
      started: () => this.started,
      reconnect: () => {
        const socket = this.socket.current();
        if (!socket || this.down.since !== null || this.tracker.state === 'needs-login') return;
        this.ctx.log.add('debug', 'link', 'Reading the object model again (new socket)');
        this.gotFirst = false;
        socket.connect();
      },
    });
    // Fallback while the socket cannot be opened (a proxy without WebSocket, a socket refused):
    // the full model by HTTP. A read, never two at once, dropped once the socket delivers again.
    this.modelPoll = this.poll({
      name: 'model (socket down)',
      read: (signal) => this.client.modelRaw(signal),
      apply: (raw) => this.onPolledModel(raw as JsonObject),
      intervalMs: () => POLL_EVERY_MS,
      when: () => this.pollDue(),
      failed: (e) => this.modelPollFailed(e),
    });
    this.pollLiveness = new Liveness({
      life: this.life,
      now: ctx.now,
      windowMs: () => POLL_SILENT_MS,
      onSilent: (quiet) => this.pollSilent(quiet),
    });
    // Without a socket the DSF session would expire: keep it alive (not while the model is polled).
    this.noopPoll = this.poll({
      name: 'noop',
      read: (signal) => this.client.noop(signal),
      apply: () => undefined,
      intervalMs: () => NOOP_EVERY_MS,
      firstDelayMs: NOOP_EVERY_MS,
      when: () => this.down.since !== null && this.sessionUsable() && !this.pollDue(),
      failed: (e) => this.sideReadFailed(e, NOOP_EVERY_MS),
    });
    this.rrfPoll = this.poll({
      name: 'rr_model (standalone)',
      read: (signal) => this.client.rrf.poll(signal),
      apply: (raw) => this.onStandaloneModel(raw as JsonObject),
      intervalMs: () => (this.ctx.detail() ? RRF_POLL_MS : RRF_TILE_POLL_MS),
      when: () => this.client.standalone && this.sessionUsable(),
      failed: (e) => this.standalonePollFailed(e),
    });
    this.client.kick = () => this.rrfPoll.kick();
    this.client.onReply = (text) => {
      for (const line of text.trim().split('\n')) {
        const level = line.startsWith('Error:') ? 'error' : line.startsWith('Warning:') ? 'warning' : 'info';
        ctx.log.add(level, 'controller', line);
      }
    };
  }

  /** The link bookkeeping (the kernel's tracker), under its former name. */
  get link(): LinkTracker {
    return this.tracker;
  }

  // ------------------------------------------------------------------ lifecycle

  protected override onStart(): void {
    this.startedAt = this.ctx.now();
    this.pollLiveness.start();
    void this.connect();
  }

  protected override onStop(): void {
    this.resyncs.reset();
    this.uploads.stopAll();
    this.connecting = null;
    this.gotFirst = false;
    this.down.back();
    if (this.client.connected) void this.client.disconnect().catch(() => undefined);
  }

  /** The login form (needs-login): the password is sent with `GET /machine/connect`. */
  async login(credentials: Record<string, string>): Promise<void> {
    this.password = credentials['password'] ?? '';
    this.authRetried = false;
    this.store.setState({ needsPassword: false });
    const ok = await this.connect();
    if (!ok && this.tracker.state === 'needs-login') throw new Error('The machine refused the password');
  }

  /** Connect: a session, then the socket. Resolves true when the session was opened. */
  private connect(): Promise<boolean> {
    if (this.connecting?.run.alive()) return this.connecting.done;
    const run = this.run();
    const done = (async () => {
      this.socket.current()?.close();
      try {
        await this.client.connect(this.password, run.signal);
      } catch (e) {
        if (!run.alive()) return false;
        if (isAuthError(e)) this.needsLogin(e);
        else {
          // A failed request (no answer, the server's own 502, a cut answer) is the link's, retried
          // quickly: back within 5 s of the fault ending.
          this.tracker.fail(asLinkFault(e));
          this.later(() => void this.connect(), quickRetry(this.ctx, this.tracker, this.startedAt));
        }
        return false;
      }
      if (!run.alive()) return false;
      const socket = this.socket.current();
      this.gotFirst = false;
      socket?.close();
      if (this.client.standalone) {
        // No socket on a standalone board: its model is polled (rrfPoll), from now on.
        this.store.setState({ transport: 'standalone', socketProblem: null });
        this.rrfPoll.kick();
        return true;
      }
      socket?.connect();
      return true;
    })().finally(() => {
      if (this.connecting?.done === done) this.connecting = null;
    });
    this.connecting = { run, done };
    return done;
  }

  /**
   * DSF refused the session. A password typed on this page is never tried again on the user's
   * behalf. Otherwise the credentials are the gateway's (the machine's configured password): they
   * are tried again on their own, slowly (a few quick tries, then once a minute, so a wrong
   * password neither hammers DSF nor locks anything), and the page says what to do meanwhile.
   */
  private needsLogin(e: unknown): void {
    this.socket.current()?.close();
    this.gotFirst = false;
    const typed = this.password !== undefined;
    const err = typed
      ? new LinkError('http', `Needs login: ${describeError(e)}`, { status: 403 })
      : new LinkError('http', PASSWORD_REFUSED, { status: 403 });
    this.tracker.fail(err, { needsLogin: true });
    this.store.setState({ needsPassword: true });
    if (typed) return;
    const delay = authRetryDelay(this.authRefusals++);
    this.tracker.patch({ retryAt: this.ctx.now() + delay });
    this.later(() => {
      if (this.tracker.state === 'needs-login' && this.password === undefined) void this.connect();
    }, delay);
  }

  /** A 401/403 (or a refused socket): renew the session once silently, then "needs login". */
  private authFailure(e: unknown): void {
    if (!this.started) return;
    if (!this.authRetried) {
      this.authRetried = true;
      this.client.forget(); // known bad
      this.ctx.log.add('debug', 'link', 'Session expired: reconnecting');
      void this.connect();
      return;
    }
    this.needsLogin(e);
  }

  private sessionUsable(): boolean {
    return this.client.connected && this.tracker.state !== 'needs-login';
  }

  // ------------------------------------------------------------------ socket

  private onSocketClose(code: number, reason: string): boolean {
    const hadModel = this.gotFirst;
    this.gotFirst = false;
    const closed = socketCloseError(code, reason, hadModel);
    if (closed.refused) {
      // DSF refuses the upgrade with 403 when the key is bad: a new session first, then a socket.
      this.authFailure(closed.error);
      return false;
    }
    this.socketFailed(closed.error);
    return true;
  }

  /** The heartbeat found the socket dead (no PONG, or no model after connecting). */
  private onSocketDead(why: string): void {
    const hadModel = this.gotFirst;
    this.gotFirst = false;
    this.socketFailed(socketDeadError(why, hadModel));
  }

  /**
   * The socket failed. While polling `GET /machine/model` works the machine stays online (the
   * data is fresh, only slower); otherwise the link is down as usual. The socket reconnects on
   * its own backoff either way.
   */
  private socketFailed(err: LinkError): void {
    if (this.down.failed()) {
      // Without the socket the session is kept by requests: one now (a gateway that holds the
      // session learns from its answer whether the session expired, and renews it).
      this.noopPoll.kick();
    }
    this.store.setState({ socketProblem: err.message });
    if (!this.down.pollingHealthy()) this.tracker.fail(err);
  }

  /** The model is polled in place of the socket (the data comes from there). */
  private polling(): boolean {
    return this.down.since !== null && this.store.getState().transport === 'polling';
  }

  /** No polled model for POLL_SILENT_MS while it is the source: the link is down. */
  private pollSilent(quietMs: number): void {
    const standalone = this.client.standalone && this.client.connected;
    if (!(this.polling() || standalone) || this.tracker.state !== 'online') return;
    this.tracker.fail(pollSilentError(quietMs, standalone));
  }

  /**
   * A model poll failed. While it is the source of data, a link fault (no answer, the console
   * server's own failure, a cut answer) is the link's at once; a dead session is renewed.
   */
  private modelPollFailed(e: unknown): number {
    if (this.polling() && !isAuthError(e) && isLinkFault(e) && this.tracker.state === 'online')
      this.tracker.fail(asLinkFault(e));
    return this.sideReadFailed(e, POLL_EVERY_MS);
  }

  private pollDue(): boolean {
    return this.down.pollTime() && this.sessionUsable();
  }

  /** A poll or noop failed: not a link failure (the socket decides); a dead session is renewed. */
  private sideReadFailed(e: unknown, retryMs: number): number {
    if (isAuthError(e) && this.client.connected) {
      // The session is gone: a new one now, then the socket (a wrong password: needs login).
      this.client.forget();
      void this.connect();
    }
    return retryMs;
  }

  private onFrame(data: string): void {
    this.pollLiveness.heard();
    const frame = this.ingest.parse(data);
    if (frame === 'pong') return;
    if (frame) {
      if (!this.gotFirst) {
        // The socket is live again: polling ends.
        this.down.back();
        this.ingest.socketBack();
        this.store.setState({ transport: 'socket', socketProblem: null });
      }
      this.ingest.frame(frame, !this.gotFirst);
      this.gotFirst = true;
    }
    // Acknowledge: the server sends nothing more until it has our OK (paced on a tile).
    this.acks.acknowledge();
  }

  private onPolledModel(raw: JsonObject): void {
    if (this.down.since === null) return; // the socket is back: it is the source
    this.down.polledOk();
    this.pollLiveness.heard();
    if (this.store.getState().transport !== 'polling') {
      this.ctx.log.add('warning', 'link', 'Live updates unavailable: polling GET /machine/model');
      this.store.setState({ transport: 'polling' });
    }
    this.ingest.polled(raw);
  }

  // ------------------------------------------------------------------ standalone (rr_*)

  private onStandaloneModel(raw: JsonObject): void {
    if (!this.client.standalone) return;
    // A silent board (a poll that does not come back) is the link down within 5 s (issue 15).
    this.pollLiveness.heard();
    this.ingest.polled(raw);
  }

  /**
   * A poll of a standalone board failed: a dead session (401/403) is renewed silently once, then
   * "needs login"; anything else is the link's (or bad data: a protocol error), retried.
   */
  private standalonePollFailed(e: unknown): number {
    if (isAuthError(e)) this.authFailure(e);
    else if (this.tracker.state !== 'needs-login')
      this.tracker.fail(e instanceof LinkError && e.kind === 'protocol' ? e : asLinkFault(e));
    return RRF_POLL_MS;
  }

  // ------------------------------------------------------------------ requests

  /** A read: on 401/403 reconnect (once) and try once more. */
  protected async read<T>(fn: (signal: AbortSignal) => Promise<T>, signal: AbortSignal): Promise<T> {
    try {
      return await fn(signal);
    } catch (e) {
      if (!isAuthError(e) || this.authRetried) throw e;
      this.authRetried = true;
      const ok = await this.connect();
      if (!ok) throw e;
      return fn(signal);
    }
  }

  /**
   * A command: sent once. A 401/403 is never resent (a command is never replayed): the session
   * reconnects in the background and the user is told to try again. While the model is polled,
   * a command that went through is followed by a poll at once (`kick`).
   */
  private async send<T>(fn: () => Promise<T>): Promise<T> {
    try {
      const r = await fn();
      this.modelPoll.kick();
      this.rrfPoll.kick();
      return r;
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
}
