import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand, CommandDecl } from '../../fleet/commands';
import type { LinkTracker, SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import { KernelSession, type RunToken } from '../../fleet/kernel';
import { gridDelay, type Poller, type SocketLink } from '../../fleet/link';
import { DuetClient, isAuthError } from './client';
import {
  asLinkFault,
  authRetryDelay,
  isLinkFault,
  Liveness,
  quickBackoff,
  quickRetry,
} from '../../fleet/faults';
import { declareCommands, uploadCommandFor, type DuetCommands, type FileArgs } from './commands';
import { ModelIngest } from './ingest';
import type { JsonObject } from './patch';
import { DEFAULT_HEIGHT_MAP, DuetReads, dirKey, type Reader } from './reads';
import { createDuetStore, type DuetState } from './state';
import { DuetUploads } from './uploads';
import type { DirEntry, HeightMap, ParsedFileInfo } from './wire';

export { messageBoxReply, validateBoxValue } from './commands';
export { HISTORY_POINTS, type CodeArgs, type DuetState, type UploadState } from './state';

/**
 * One Duet (DSF) machine on the session kernel: `GET /machine/connect` (through the gateway: no
 * key, the gateway holds the DSF session; a key only where msw answers, in tests), then `WS /machine` for
 * the object model (full model, then patches, `OK\n` after each). The socket's liveness is its
 * declared heartbeat: `PING\n` after 2 s of silence, dead when nothing answers within 2.5 s more
 * (or when the first model is 6 s late), then the socket reconnects on its backoff. Session
 * problems (a refused upgrade, 401/403) renew the session silently once, then show "needs
 * login". Close codes 1001/1011 mean the DSF service (or the link to it) is down; 1007 that the
 * console server refused a frame of the Duet's. While the socket stays down, the model is polled
 * (`GET /machine/model`) and the session kept alive (`GET /machine/noop`).
 *
 * Bad data (issue 15): a frame that is no JSON object, nests too deep, or would make the model
 * invalid is dropped, shown as a protocol error and logged; the last valid model stays, and a new
 * socket reads the model whole again (at most every RESYNC_EVERY_MS). The session lives on.
 *
 * The console history is the machine's log (ctx.log), which outlives sockets and reconnects.
 */

/**
 * Liveness (issue 15: a silent link is down within 5 s): `PING\n` after 2 s without a frame (the
 * rule is checked every 0.5 s), and dead when nothing answers within 2.5 s more. Through the
 * console server a PING is answered by the server itself, which keeps the one socket to DSF and
 * pings it on its own (sharing.ts `ping`, gateway/streams.ts): a Duet silent for 4.5 s is noticed
 * there and every page socket closed (1011), which this session shows as the link down. The
 * protocol document says updates may pause ("if the client does not receive an update for a
 * while"), so silence without a PING is not death. While the model is polled instead, a poll
 * that fails or no polled model for POLL_SILENT_MS is the link down.
 */
export const PING_AFTER_MS = 2000;
export const DEAD_AFTER_MS = 2500;
/** From connecting to the full model. */
export const FIRST_MODEL_MS = 6000;
/**
 * The DSF refused the credentials that are not this page's (the machine's configured password, or
 * none): why, what to do, and that it is tried again on its own.
 */
export const PASSWORD_REFUSED =
  'The Duet refused the password (HTTP 403): check this machine\'s "password" in the machines file, or log in here. It is tried again on its own, at most once a minute.';
export const NOOP_EVERY_MS = 4000;
/** While the socket cannot be opened, the object model is polled this often (`GET /machine/model`). */
export const POLL_EVERY_MS = 2000;
/** Polling starts only when the socket has been down this long (a quick reconnect needs none). */
export const POLL_AFTER_MS = 5000;
/**
 * While the model is polled, no good answer for this long is silence: the link is down (issue 15:
 * within 5 s). Two polls missed, and a little slack.
 */
export const POLL_SILENT_MS = 4500;
/**
 * A dropped frame (bad data) makes the model read again by a new socket (its first frame is the
 * full model), at most this often: bad data on every frame must not churn sockets.
 */
export const RESYNC_EVERY_MS = 10_000;
/**
 * A standalone board (RepRapFirmware without an SBC, `rr_*`): the model is polled this often
 * (Duet Web Control polls every 250 ms from each page; through the console server one session
 * serves every viewer, and a board has few HTTP connections: once a second). It also keeps the
 * session, which RRF drops after 8 s of silence.
 */
export const RRF_POLL_MS = 1000;
/** A standalone board shown only on a tile (no page of it open): `rr_model` at the tile's pace. */
export const RRF_TILE_POLL_MS = 2000;
/**
 * Shown only on a tile, the socket's model updates come at most this often: the `OK` that asks
 * for the next patch waits until this long after the last one. The sender (DSF, or the console
 * server's shared socket) then sends one patch with every change made meanwhile, so nothing is
 * lost, and an idle fleet page is not woken four times a second per printer (issue 16). On the
 * machine's page every patch is acknowledged at once, as Duet Web Control does.
 */
export const TILE_ACK_MS = 1000;

export class DuetSession extends KernelSession {
  readonly client: DuetClient;
  readonly store: StoreApi<DuetState>;
  /** On-demand reads (listings, file info, height map) as queries of this machine. */
  readonly reads: DuetReads;
  readonly cmd: DuetCommands;
  readonly commands: Readonly<Record<string, AnyCommand>>;

  private readonly ingest: ModelIngest;
  private readonly uploads: DuetUploads;
  private readonly socket: { current: () => SocketLink | null };
  /** When the last `OK` went (tile pacing), and whether one waits to go. */
  private lastAckAt = 0;
  private ackWaiting: { generation: number } | null = null;
  /** `GET /machine/model` while the socket has been down for POLL_AFTER_MS. */
  private readonly modelPoll: Poller;
  /** `GET /machine/noop` while the socket is down (and the model is not polled yet). */
  private readonly noopPoll: Poller;
  /** A standalone board: `rr_model` (live parts, changed parts, the reply) every RRF_POLL_MS. */
  private readonly rrfPoll: Poller;
  /** The current socket delivered its full model (later frames are patches). */
  private gotFirst = false;
  /** Since when the socket does not deliver (null: it does, or it was never opened). */
  private socketDownSince: number | null = null;
  private lastPollOkAt = 0;
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
  /** The last model re-read after a dropped frame, and whether one is waiting its turn. */
  private lastResyncAt = -Infinity;
  private resyncDue = false;

  constructor(ctx: SessionContext) {
    super(ctx);
    this.client = new DuetClient(ctx.machine.id);
    this.store = createDuetStore();
    this.ingest = new ModelIngest({
      ctx,
      tracker: this.tracker,
      store: this.store,
      accepted: () => {
        this.authRetried = false;
        this.authRefusals = 0;
      },
      resync: () => this.resync(),
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
      when: () => this.socketDownSince !== null && this.sessionUsable() && !this.pollDue(),
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
    this.resyncDue = false;
    this.uploads.stopAll();
    this.connecting = null;
    this.gotFirst = false;
    this.socketDownSince = null;
    this.lastPollOkAt = 0;
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
    if (code === 1008 || code === 4403) {
      // DSF refuses the upgrade with 403 when the key is bad: a new session first, then a socket.
      this.authFailure(new LinkError('http', `socket refused (${reason || code})`, { status: 403 }));
      return false;
    }
    const why = reason ? `: ${reason}` : '';
    if (code === 1007) {
      // The console server refused a frame of the Duet's (bad data): shown as such; the socket
      // reconnects and the full model is read again.
      this.socketFailed(
        new LinkError('protocol', `WS /machine: the Duet sent data the console cannot use${why}`, {
          path: '(root)',
        }),
      );
      return true;
    }
    this.socketFailed(
      code === 1001 || code === 1011
        ? // DSF's own "going away / unavailable", or the console server closing for a Duet that
          // stopped answering: the link is down either way (never a verdict on the Duet).
          new LinkError(
            'network',
            `The Duet service (DSF) or the link to it is down: socket closed with ${code}${reason ? ` (${reason})` : ''}`,
          )
        : new LinkError(
            'network',
            `Socket closed (${code}${why})${hadModel ? '' : ' before the object model arrived'}`,
          ),
    );
    return true;
  }

  /** The heartbeat found the socket dead (no PONG, or no model after connecting). */
  private onSocketDead(why: string): void {
    const hadModel = this.gotFirst;
    this.gotFirst = false;
    this.socketFailed(
      new LinkError(
        'timeout',
        hadModel ? `${why}: the link is dead` : `The object model did not arrive (${why.toLowerCase()})`,
      ),
    );
  }

  /**
   * The socket failed. While polling `GET /machine/model` works the machine stays online (the
   * data is fresh, only slower); otherwise the link is down as usual. The socket reconnects on
   * its own backoff either way.
   */
  private socketFailed(err: LinkError): void {
    if (this.socketDownSince === null) {
      this.socketDownSince = this.ctx.now();
      // Without the socket the session is kept by requests: one now (a gateway that holds the
      // session learns from its answer whether the session expired, and renews it).
      this.noopPoll.kick();
    }
    this.store.setState({ socketProblem: err.message });
    if (!this.pollingHealthy()) this.tracker.fail(err);
  }

  private pollingHealthy(): boolean {
    return this.lastPollOkAt > 0 && this.ctx.now() - this.lastPollOkAt < POLL_SILENT_MS;
  }

  /** The model is polled in place of the socket (the data comes from there). */
  private polling(): boolean {
    return this.socketDownSince !== null && this.store.getState().transport === 'polling';
  }

  /** No polled model for POLL_SILENT_MS while it is the source: the link is down. */
  private pollSilent(quietMs: number): void {
    const standalone = this.client.standalone && this.client.connected;
    if (!(this.polling() || standalone) || this.tracker.state !== 'online') return;
    this.tracker.fail(
      new LinkError(
        'timeout',
        `No answer from the Duet for ${Math.round(quietMs / 1000)} s (${
          standalone ? 'GET /rr_model' : 'GET /machine/model; the live socket is down'
        })`,
      ),
    );
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
    const down = this.socketDownSince;
    return down !== null && this.ctx.now() - down >= POLL_AFTER_MS && this.sessionUsable();
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
        this.socketDownSince = null;
        this.lastPollOkAt = 0;
        this.ingest.socketBack();
        this.store.setState({ transport: 'socket', socketProblem: null });
      }
      this.ingest.frame(frame, !this.gotFirst);
      this.gotFirst = true;
    }
    // Acknowledge: the server sends nothing more until it has our OK (paced on a tile).
    this.acknowledge();
  }

  /** The `OK` after a frame: at once on the machine's page, at the tile's pace otherwise. */
  private acknowledge(): void {
    const socket = this.socket.current();
    if (!socket) return;
    // One `OK` per frame: the sender waits for it, so at most one is ever waiting per socket.
    if (this.ackWaiting?.generation === socket.generation) return;
    const now = this.ctx.now();
    // On the grid of the tiles' polls (gridDelay), the next grid moment after the last `OK`.
    const wait = this.ctx.detail()
      ? 0
      : gridDelay(Math.max(now, this.lastAckAt), TILE_ACK_MS) + Math.max(0, this.lastAckAt - now);
    if (wait <= 0) {
      this.ackWaiting = null;
      this.lastAckAt = now;
      socket.send('OK\n');
      return;
    }
    const mine = { generation: socket.generation };
    this.ackWaiting = mine;
    this.later(() => {
      if (this.ackWaiting !== mine) return;
      this.ackWaiting = null;
      // Only on the socket that sent the frame: a new socket starts with a full model of its own.
      if (this.socket.current() !== socket || socket.generation !== mine.generation) return;
      this.lastAckAt = this.ctx.now();
      socket.send('OK\n');
    }, wait);
  }

  /**
   * A frame was dropped (bad data: shown as a protocol error, logged): the model may now differ
   * from the machine's. A new socket reads it whole (DSF sends the full model first), now or when
   * RESYNC_EVERY_MS has passed since the last time; the session and its link stay as they are.
   */
  private resync(): void {
    if (this.resyncDue || !this.started) return;
    this.resyncDue = true;
    const wait = Math.max(0, this.lastResyncAt + RESYNC_EVERY_MS - this.ctx.now());
    this.later(() => {
      if (!this.resyncDue) return;
      this.resyncDue = false;
      this.lastResyncAt = this.ctx.now();
      const socket = this.socket.current();
      if (!socket || this.socketDownSince !== null || this.tracker.state === 'needs-login') return;
      this.ctx.log.add('debug', 'link', 'Reading the object model again (new socket)');
      this.gotFirst = false;
      socket.connect();
    }, wait);
  }

  private onPolledModel(raw: JsonObject): void {
    if (this.socketDownSince === null) return; // the socket is back: it is the source
    this.lastPollOkAt = this.ctx.now();
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
  private async read<T>(fn: (signal: AbortSignal) => Promise<T>, signal: AbortSignal): Promise<T> {
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

  // ------------------------------------------------------------------ files and page state

  /** Which upload command applies to a directory (operator only into the jobs folder). */
  uploadCommandFor(dir: string): CommandDecl<FileArgs> {
    return uploadCommandFor(this.cmd, dir);
  }

  cancelUpload(id: number): void {
    this.uploads.cancel(id);
  }

  /** Shows `dir` in the Files tab (its listing is a query the tab reads). */
  openDir(dir: string): void {
    this.store.setState({ filesDir: dir });
  }

  /** Shows `dir` and reads its listing (cached for DIR_STALE_MS). */
  loadDir(dir: string): Promise<DirEntry[]> {
    this.openDir(dir);
    return this.reads.listDir(dir);
  }

  /** Reads the shown folder again. */
  refreshDir(): Promise<void> {
    return this.ctx.queries.invalidate(dirKey(this.store.getState().filesDir));
  }

  loadFileInfo(path: string): Promise<ParsedFileInfo> {
    return this.reads.loadFileInfo(path);
  }

  /** The height map `move.compensation.file` names (default `0:/sys/heightmap.csv`). */
  heightMapPath(): string {
    return this.store.getState().model?.move.compensation?.file ?? DEFAULT_HEIGHT_MAP;
  }

  loadHeightMap(): Promise<HeightMap> {
    return this.reads.loadHeightMap(this.heightMapPath());
  }

  download(path: string): Promise<Blob> {
    return this.read((signal) => this.client.download(path, signal), this.signal);
  }

  dismissBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: [...s.dismissedBoxes.slice(-20), seq] }));
  }

  /** Show a hidden message box again. */
  reopenBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: s.dismissedBoxes.filter((d) => d !== seq) }));
  }
}
