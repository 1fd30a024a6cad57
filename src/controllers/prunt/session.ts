import type { StoreApi } from 'zustand/vanilla';
import type { AnyCommand } from '../../fleet/commands';
import type { SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import { createSharedStore, KernelSession, type RunToken } from '../../fleet/kernel';
import type { Poller, SocketLink } from '../../fleet/link';
import { UploadTracker } from '../../fleet/upload';
import type { DraftStorage } from '../../forms/storage';
import { PruntClient } from './client';
import { declarePruntCommands, type PruntCommands } from './commands';
import type { PruntConfig } from './config';
import { asLinkFault, isLinkFault, quickBackoff, quickRetry } from '../../fleet/faults';
import { History } from './history';
import { PruntLive } from './live';
import { ALWAYS_FRESH, PRUNT_KEYS } from './queries';
import {
  divisorFor,
  FLEET_DIVISOR,
  initialConfigState,
  initialPruntState,
  SILENCE_MS,
  type ConfigState,
  type PruntState,
} from './state';
import { buildStatusModel } from './status';

export type { PruntCommands } from './commands';
export {
  divisorFor,
  FLEET_DIVISOR,
  LIVE_RATES,
  SILENCE_MS,
  TICK_MS,
  type ConfigState,
  type GcodeEntry,
  type PruntState,
} from './state';

/**
 * A Prunt machine on the session kernel: one WebSocket (`/websocket/everything`) for status,
 * logs and command progress, alive while it ticks (heartbeat: 3 s of silence is a dead socket);
 * HTTP for schemas, config, files and commands. What the frames mean is `live.ts`, the config
 * editor `config.ts`, the commands `commands.ts`, the on-demand read keys `queries.ts`.
 */

/** While idle, the status read that follows a command wakes this seldom (and does nothing). */
const KICK_IDLE_MS = 60_000;

export interface PruntSessionOptions {
  drafts?: DraftStorage;
  client?: PruntClient;
}

export class PruntSession extends KernelSession {
  readonly client: PruntClient;
  readonly store: StoreApi<PruntState> = createSharedStore<PruntState>(initialPruntState);
  readonly history = new History(600);
  /** The file upload in progress or last finished (the console's one upload state). */
  readonly uploads = new UploadTracker();
  /** The config editor's store: its views read it; the editor's code loads when it opens. */
  readonly config: StoreApi<ConfigState> = createSharedStore<ConfigState>(initialConfigState);
  /**
   * The config editor (schema → form, drafts, save): the form engine is a chunk of its own, loaded
   * when the editor first opens (issue 16: nothing else on a Prunt page needs it).
   */
  private editorLoad: Promise<PruntConfig> | null = null;
  private readonly drafts: DraftStorage | undefined;
  readonly cmd: PruntCommands;
  readonly commands: Readonly<Record<string, AnyCommand>>;
  private readonly live: PruntLive;
  private readonly socket: { current: () => SocketLink | null };
  private readonly statusRead: Poller;
  private watchers = 0;
  private kickPending = false;
  /** When this run started (an outage is measured from the last good data or this). */
  private startedAt = 0;
  /** The status schema read in flight (one at a time), whether to read once more after it, and its end. */
  private schemaRead: { run: RunToken; again: boolean; done: Promise<void> } | null = null;
  /** A retry of a failed status schema read is due (one retry loop per run). */
  private schemaRetry: RunToken | null = null;

  constructor(ctx: SessionContext, opts: PruntSessionOptions = {}) {
    super(ctx);
    this.client = opts.client ?? new PruntClient(ctx.machine.id);
    this.drafts = opts.drafts;
    this.live = new PruntLive(ctx, this.store, this.history, this.tracker, () => this.serverRestarted());
    this.socket = this.stream(() => ({
      url: () => `${this.client.http.base}/websocket/everything`,
      // Up to 10 ticks a second on a machine page: one render per frame, none dropped.
      coalesce: true,
      // Quick reconnects while the outage is young: back within 5 s of the fault ending.
      backoff: quickBackoff(ctx, () => this.startedAt),
      heartbeat: {
        silenceMs: SILENCE_MS,
        firstMessageMs: SILENCE_MS,
        onDead: (why) =>
          this.tracker.fail(new LinkError('timeout', `No status from the controller (${why})`)),
      },
      onOpen: () => {
        this.sendDivisor();
        // The HTTP side failed earlier (controller was down): try again now it answers.
        if (!this.store.getState().statusModel) void this.connectHttp();
      },
      onMessage: (text) => this.live.message(text),
      onClose: (code, reason) => {
        this.linkLost(`Live connection closed (${code}${reason ? `: ${reason}` : ''})`);
        return true;
      },
    }));
    // The socket is the status source; after a command one `GET /status/values` shows its effect
    // at once instead of at the next tick (up to 1 s at the fleet rate). Only when kicked.
    this.statusRead = this.poll({
      name: 'status after a command',
      when: () => this.kickPending,
      read: (signal) => {
        this.kickPending = false;
        return this.client.statusValues(signal);
      },
      apply: (wire) => this.live.values(wire),
      intervalMs: () => KICK_IDLE_MS,
      firstDelayMs: KICK_IDLE_MS,
      // A missed extra read is no link failure: the socket still says how the link is.
      failed: (e) => {
        this.ctx.log.add('debug', 'link', `Status read after a command: ${describeError(e)}`);
        return KICK_IDLE_MS;
      },
    });
    const { cmd, all } = declarePruntCommands(this);
    this.cmd = cmd;
    this.commands = all;
  }

  protected override onStart(): void {
    this.kickPending = false;
    this.startedAt = this.ctx.now();
    this.schemaRead = null;
    this.schemaRetry = null;
    void this.connectHttp();
  }

  /** Read the status once, right after any read in flight (a command changed it). */
  kick(): void {
    if (!this.started) return;
    this.kickPending = true;
    this.statusRead.kick();
  }

  /**
   * Status schema (which also tells the API generation) and the last update check. One read at a
   * time: asked again while one is in flight (a server restart, a socket that opened), it reads
   * once more right after it; a failure schedules one retry, not one per caller.
   */
  private connectHttp(): Promise<void> {
    const run = this.run();
    if (!run.alive()) return Promise.resolve();
    if (this.schemaRead?.run.alive()) {
      this.schemaRead.again = true;
      return this.schemaRead.done;
    }
    const read = { run, again: false, done: Promise.resolve() };
    this.schemaRead = read;
    read.done = (async () => {
      try {
        do {
          read.again = false;
          await this.readSchema(run);
        } while (read.again && run.alive());
      } finally {
        if (this.schemaRead === read) this.schemaRead = null;
      }
    })();
    return read.done;
  }

  private async readSchema(run: RunToken): Promise<void> {
    try {
      const wire = await this.ctx.queries.fetch(
        PRUNT_KEYS.statusSchema,
        (signal) => this.client.statusSchema(signal),
        ALWAYS_FRESH,
      );
      if (!run.alive()) return;
      this.store.setState({ api: wire.api, statusModel: buildStatusModel(wire) });
      await this.refreshUpdateCheck();
    } catch (e) {
      if (!run.alive()) return;
      // A failed request (no answer, the server's own 502, a cut answer) is the link's; an answer
      // of another shape a protocol error. Neither is final: asked again (and on the next socket).
      this.tracker.fail(isLinkFault(e) ? asLinkFault(e) : e);
      this.ctx.log.warn('link', `Status schema: ${describeError(e)}`);
      if (this.schemaRetry?.alive()) return;
      this.schemaRetry = run;
      this.later(
        () => {
          this.schemaRetry = null;
          if (!this.store.getState().statusModel) void this.connectHttp();
        },
        quickRetry(this.ctx, this.tracker, this.startedAt),
      );
    }
  }

  /**
   * A new server start time: schema, update check and (when open) the config editor again, after
   * the status schema (it says which API generation the restarted server speaks).
   */
  private serverRestarted(): void {
    const run = this.run();
    void this.connectHttp().then(() => {
      if (run.alive() && this.config.getState().phase !== 'idle')
        void this.loadConfig('The server restarted: schema and values were fetched again.');
    });
  }

  /** The controller's last update check ("may reply with 500 if the update check times out"). */
  async refreshUpdateCheck(): Promise<void> {
    const api = this.store.getState().api;
    const run = this.run();
    if (!api || !run.alive()) return;
    try {
      const result = await this.ctx.queries.fetch(
        PRUNT_KEYS.updateCheck(api),
        (signal) => this.client.updateCheck(api, signal),
        ALWAYS_FRESH,
      );
      if (run.alive()) this.store.setState({ update: { result, error: null } });
    } catch (e) {
      if (run.alive()) this.store.setState({ update: { result: null, error: describeError(e) } });
    }
  }

  /** The uploads list is an on-demand read (`useMachineQuery` in the Files tab): read it again. */
  refreshFiles(): Promise<void> {
    return this.ctx.queries.invalidate(PRUNT_KEYS.files);
  }

  // --- Live rate -------------------------------------------------------------------------------

  /**
   * A machine page shows live data: ask for more ticks while it watches. Returns the "stop
   * watching" function. With no watcher the fleet rate (1 per second) applies.
   */
  watchLive(): () => void {
    this.watchers++;
    this.sendDivisor();
    let done = false;
    return () => {
      if (done) return;
      done = true;
      this.watchers = Math.max(0, this.watchers - 1);
      this.sendDivisor();
    };
  }

  setLiveRate(hz: number): void {
    this.store.setState({ liveHz: hz });
    this.sendDivisor();
  }

  private sendDivisor(): void {
    const divisor = this.watchers > 0 ? divisorFor(this.store.getState().liveHz) : FLEET_DIVISOR;
    this.store.setState({ divisor });
    this.socket.current()?.send(String(divisor));
  }

  // --- Config ----------------------------------------------------------------------------------

  /** The editor's code, loaded once (a failed load is tried again on the next call). */
  private editor(): Promise<PruntConfig> {
    this.editorLoad ??= Promise.all([import('./config'), import('../../forms/storage')]).then(
      ([{ PruntConfig }, { defaultDraftStorage }]) =>
        new PruntConfig({
          machineId: this.ctx.machine.id,
          client: this.client,
          queries: this.ctx.queries,
          drafts: this.drafts ?? defaultDraftStorage(),
          now: this.ctx.now,
          run: () => this.run(),
          api: () => this.store.getState().api,
          store: this.config,
        }),
      (e: unknown) => {
        this.editorLoad = null;
        const why = e instanceof Error ? e.message : String(e);
        this.config.setState({
          phase: 'error',
          error: `The console could not load its config editor (${why}). Reload the page.`,
        });
        throw e;
      },
    );
    return this.editorLoad;
  }

  /** Open the editor: schema + values (once; again after a save or a server restart). */
  async openConfig(): Promise<void> {
    // "Loading" at once, also while the editor's code is on its way.
    if (this.config.getState().phase !== 'ready') this.config.setState({ phase: 'loading', error: null });
    return (await this.editor()).open();
  }

  async loadConfig(notice: string | null): Promise<void> {
    return (await this.editor()).load(notice);
  }

  async saveConfig(commandId: string): Promise<string> {
    return (await this.editor()).save(commandId);
  }
}
