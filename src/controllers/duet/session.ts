import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand, CommandDecl } from '../../fleet/commands';
import type { LinkTracker, SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import { KernelSession, type RunToken } from '../../fleet/kernel';
import type { Poller, SocketLink } from '../../fleet/link';
import { DuetClient, isAuthError } from './client';
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
 * declared heartbeat: `PING\n` after 2 s of silence, dead when nothing answers within 4 s more
 * (or when the first model is 6 s late), then the socket reconnects on its backoff. Session
 * problems (a refused upgrade, 401/403) renew the session silently once, then show "needs
 * login". Close codes 1001/1011 mean the DSF service is down. While the socket stays down, the
 * model is polled (`GET /machine/model`) and the session kept alive (`GET /machine/noop`).
 *
 * The console history is the machine's log (ctx.log), which outlives sockets and reconnects.
 */

export const PING_AFTER_MS = 2000;
export const DEAD_AFTER_MS = 4000;
export const NOOP_EVERY_MS = 4000;
/** While the socket cannot be opened, the object model is polled this often (`GET /machine/model`). */
export const POLL_EVERY_MS = 2000;
/** Polling starts only when the socket has been down this long (a quick reconnect needs none). */
export const POLL_AFTER_MS = 5000;

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
  /** `GET /machine/model` while the socket has been down for POLL_AFTER_MS. */
  private readonly modelPoll: Poller;
  /** `GET /machine/noop` while the socket is down (and the model is not polled yet). */
  private readonly noopPoll: Poller;
  /** The current socket delivered its full model (later frames are patches). */
  private gotFirst = false;
  /** Since when the socket does not deliver (null: it does, or it was never opened). */
  private socketDownSince: number | null = null;
  private lastPollOkAt = 0;
  private authRetried = false;
  private password: string | undefined;
  private connecting: { run: RunToken; done: Promise<boolean> } | null = null;

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
      },
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
      // Opened once a session is there (onStart → connect), reconnected on its own backoff.
      autoConnect: false,
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
        firstMessageMs: PING_AFTER_MS + DEAD_AFTER_MS,
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
      failed: (e) => this.sideReadFailed(e, POLL_EVERY_MS),
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
  }

  /** The link bookkeeping (the kernel's tracker), under its former name. */
  get link(): LinkTracker {
    return this.tracker;
  }

  // ------------------------------------------------------------------ lifecycle

  protected override onStart(): void {
    void this.connect();
  }

  protected override onStop(): void {
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
        else this.later(() => void this.connect(), this.tracker.fail(e));
        return false;
      }
      if (!run.alive()) return false;
      const socket = this.socket.current();
      this.gotFirst = false;
      socket?.close();
      socket?.connect();
      return true;
    })().finally(() => {
      if (this.connecting?.done === done) this.connecting = null;
    });
    this.connecting = { run, done };
    return done;
  }

  private needsLogin(e: unknown): void {
    this.socket.current()?.close();
    this.gotFirst = false;
    const err = new LinkError('http', `Needs login: ${describeError(e)}`, { status: 403 });
    this.tracker.fail(err, { needsLogin: true });
    this.store.setState({ needsPassword: true });
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
    this.socketFailed(
      code === 1001 || code === 1011
        ? new LinkError(
            'vendor',
            `The Duet service (DSF) is down: socket closed with ${code}${reason ? ` (${reason})` : ''}`,
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
    return this.lastPollOkAt > 0 && this.ctx.now() - this.lastPollOkAt < POLL_EVERY_MS * 3;
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
    // Acknowledge: the server sends nothing more until it has our OK.
    this.socket.current()?.send('OK\n');
  }

  private onPolledModel(raw: JsonObject): void {
    if (this.socketDownSince === null) return; // the socket is back: it is the source
    this.lastPollOkAt = this.ctx.now();
    if (this.store.getState().transport !== 'polling') {
      this.ctx.log.add('warning', 'link', 'Live updates unavailable: polling GET /machine/model');
      this.store.setState({ transport: 'polling' });
    }
    this.ingest.polled(raw);
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
