import { createStore, type StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../../fleet/contract';
import { describeError, LinkError, protocolError } from '../../fleet/errors';
import type { UploadProgress } from '../../fleet/http';
import { SocketLink } from '../../fleet/link';
import type { MachineInfo } from '../../fleet/types';
import { valuesEqual } from '../../forms/ir';
import { FormModel } from '../../forms/model';
import { defaultDraftStorage, type DraftStorage } from '../../forms/storage';
import { PruntClient } from './client';
import {
  buildFlatPatch,
  buildForm,
  buildModulePatch,
  placeErrors,
  readValues,
  type PruntApi,
  type PruntForm,
} from './config-ir';
import { History } from './history';
import {
  activityOf,
  alarmsOf,
  buildStatusModel,
  derive,
  jobOf,
  normalizeFlat,
  type StatusModule,
  type StatusValues,
} from './status';
import { wsMessageSchema, type SmartPlug, type StartupState, type UpdateCheck, type WsMessage } from './wire';

/**
 * A Prunt machine: one WebSocket (`/websocket/everything`) for status, logs and command
 * progress; HTTP for schemas, config, files and commands. The config editor's values are
 * fetched when it opens and after a save — never polled (on the flat API each GET rewrites
 * the config file on the controller).
 */

/** Status ticks are every 50 ms; the divisor asks for every Nth. */
export const TICK_MS = 50;
/** Fleet view: 1 per second. */
export const FLEET_DIVISOR = 20;
export const LIVE_RATES = [1, 2, 5, 10] as const;

export function divisorFor(hz: number): number {
  const h = Math.min(10, Math.max(0.1, hz));
  return Math.max(1, Math.round(1000 / TICK_MS / h));
}

export interface GcodeEntry {
  seq: number;
  at: number;
  command: string;
  id: string | null;
  state: 'sending' | 'sent' | 'Running' | 'Completed' | 'Cancelled' | 'Failed' | 'error' | string;
  output: string[];
}

export interface PruntState {
  api: PruntApi | null;
  startTime: string | null;
  startup: StartupState | null;
  statusModel: StatusModule[] | null;
  status: StatusValues;
  statusAt: number | null;
  smartPlug: SmartPlug | null;
  exception: { message: string; fatal: boolean } | null;
  update: { result: UpdateCheck | null; error: string | null } | null;
  files: string[] | null;
  filesError: string | null;
  upload: { name: string; loaded: number; total: number; error: string | null; done: boolean } | null;
  gcode: GcodeEntry[];
  /** Ticks per second asked of the controller while a machine page watches (user-selectable). */
  liveHz: number;
  divisor: number;
}

export interface ConfigState {
  phase: 'idle' | 'loading' | 'ready' | 'error';
  error: string | null;
  form: PruntForm | null;
  model: FormModel | null;
  saving: boolean;
  lastSave: { at: number; saved: boolean; message: string } | null;
  /** A save went through: offer "reload the server to apply". */
  offerReload: boolean;
  /** Told after a server restart / schema change. */
  notice: string | null;
}

export interface PruntCommands {
  pause: CommandDecl<void>;
  resume: CommandDecl<void>;
  cancel: CommandDecl<void>;
  runFile: CommandDecl<string>;
  runCommand: CommandDecl<string>;
  saveConfig: CommandDecl<void>;
  reloadServer: CommandDecl<void>;
  allowFirmwareUpdate: CommandDecl<void>;
  upload: CommandDecl<{ name: string; body: Blob | string }>;
}

export interface PruntSessionOptions {
  drafts?: DraftStorage;
  client?: PruntClient;
}

export class PruntSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly client: PruntClient;
  readonly store: StoreApi<PruntState>;
  readonly config: StoreApi<ConfigState>;
  readonly history = new History(600);
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  readonly cmd: PruntCommands;
  private readonly tracker: LinkTracker;
  private readonly drafts: DraftStorage;
  private socket: SocketLink | null = null;
  private watchers = 0;
  private started = false;
  private lastMessageAt = 0;
  private watchdog: ReturnType<typeof setInterval> | null = null;
  private alarmSince = new Map<string, number>();
  private jobStartedAt: number | null = null;
  private jobName: string | null = null;
  private gcodeSeq = 0;
  private connecting: Promise<void> | null = null;

  constructor(
    readonly ctx: SessionContext,
    opts: PruntSessionOptions = {},
  ) {
    this.machine = ctx.machine;
    this.client = opts.client ?? new PruntClient(ctx.machine.id);
    this.drafts = opts.drafts ?? defaultDraftStorage();
    this.tracker = new LinkTracker(ctx);
    this.store = createStore<PruntState>(() => ({
      api: null,
      startTime: null,
      startup: null,
      statusModel: null,
      status: {},
      statusAt: null,
      smartPlug: null,
      exception: null,
      update: null,
      files: null,
      filesError: null,
      upload: null,
      gcode: [],
      liveHz: 5,
      divisor: FLEET_DIVISOR,
    }));
    this.config = createStore<ConfigState>(() => ({
      phase: 'idle',
      error: null,
      form: null,
      model: null,
      saving: false,
      lastSave: null,
      offerReload: false,
      notice: null,
    }));
    this.cmd = this.declare();
    this.commands = Object.fromEntries(Object.values(this.cmd).map((c: CommandDecl<never>) => [c.id, c]));
  }

  // --- Lifecycle -------------------------------------------------------------------------------

  start(): void {
    if (this.started) return;
    this.started = true;
    this.socket = new SocketLink({
      coalesce: true,
      url: () => `${this.client.http.base}/websocket/everything`,
      autoConnect: true,
      onOpen: () => {
        this.lastMessageAt = this.ctx.now();
        this.sendDivisor();
        // The HTTP side failed earlier (controller was down): try again now it answers.
        if (!this.store.getState().statusModel) void this.connectHttp();
      },
      onMessage: (d) => this.onMessage(d),
      onClose: (code, reason) => {
        if (!this.started) return false;
        this.tracker.fail(
          new LinkError('network', `Live connection closed (${code}${reason ? `: ${reason}` : ''})`),
        );
        return true;
      },
    });
    // A socket that stays open but says nothing for 10 s is dead: reconnect.
    this.watchdog = setInterval(() => {
      if (this.socket?.open && this.ctx.now() - this.lastMessageAt > 10_000) {
        this.tracker.fail(new LinkError('timeout', 'No status from the controller for 10 s'));
        this.socket.restart();
      }
    }, 5_000);
    void this.connectHttp();
  }

  stop(): void {
    this.started = false;
    this.socket?.close();
    this.socket = null;
    if (this.watchdog) clearInterval(this.watchdog);
    this.watchdog = null;
  }

  /** Status schema (which also tells the API generation) and the last update check. */
  private connectHttp(): Promise<void> {
    this.connecting ??= (async () => {
      try {
        const wire = await this.client.statusSchema();
        this.store.setState({ api: wire.api, statusModel: buildStatusModel(wire) });
        try {
          const result = await this.client.updateCheck(wire.api);
          this.store.setState({ update: { result, error: null } });
        } catch (e) {
          // "May reply with 500 if the update check times out."
          this.store.setState({ update: { result: null, error: describeError(e) } });
        }
      } catch (e) {
        this.tracker.fail(e);
        this.ctx.log.warn('link', `Status schema: ${describeError(e)}`);
      } finally {
        this.connecting = null;
      }
    })();
    return this.connecting;
  }

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
    this.socket?.send(String(divisor));
  }

  // --- Socket messages -------------------------------------------------------------------------

  private onMessage(text: string): void {
    this.lastMessageAt = this.ctx.now();
    let json: unknown;
    try {
      json = JSON.parse(text);
    } catch {
      this.ctx.log.warn('protocol', `Live message is not JSON: ${text.slice(0, 80)}`);
      return;
    }
    const r = wsMessageSchema.safeParse(json);
    if (!r.success) {
      // A malformed status message is a visible protocol error (with its path) until a good one arrives.
      this.tracker.fail(protocolError('/websocket/everything', r.error));
      return;
    }
    this.handle(r.data);
  }

  private handle(m: WsMessage): void {
    const s = this.store.getState();
    switch (m.type) {
      case 'start': {
        const restarted = s.startTime !== null && s.startTime !== m.startTime;
        this.store.setState({ startTime: m.startTime });
        if (restarted) {
          this.ctx.log.info('controller', `Server restarted (start time ${m.startTime})`);
          this.history.clear();
          void this.connectHttp();
          if (this.config.getState().phase !== 'idle')
            void this.loadConfig('The server restarted: schema and values were fetched again.');
        }
        return;
      }
      case 'tick': {
        const values = m.api === 'flat' ? normalizeFlat(m.values) : m.values;
        const patch: Partial<PruntState> = { status: values, statusAt: this.ctx.now(), startup: m.startup };
        if (m.api === 'module') {
          patch.smartPlug = m.smartPlug;
          if (JSON.stringify(m.exception) !== JSON.stringify(s.exception)) {
            patch.exception = m.exception;
            if (m.exception)
              this.ctx.log.add(
                m.exception.fatal ? 'error' : 'warning',
                'controller',
                `Server exception: ${m.exception.message.trim()}`,
              );
          }
        }
        if (m.startup !== s.startup && m.startup) this.ctx.log.info('controller', `Startup: ${m.startup}`);
        this.store.setState(patch);
        this.updateSnapshot();
        return;
      }
      case 'log': {
        const text = m.text.replace(/\s+$/, '');
        this.ctx.log.add(/error|raised|exception|fail/i.test(text) ? 'error' : 'info', 'controller', text);
        return;
      }
      case 'gcode': {
        this.store.setState((st) => ({
          gcode: st.gcode.map((g) =>
            g.id === m.id
              ? { ...g, state: m.kind, output: m.message ? [...g.output, m.message] : g.output }
              : g,
          ),
        }));
        if (m.kind === 'Failed') this.ctx.log.error('console', `G-code ${m.id} failed: ${m.message ?? ''}`);
        else if (m.kind === 'Output' && m.message) this.ctx.log.info('console', m.message);
        return;
      }
      case 'unknown':
        this.ctx.log.add('debug', 'protocol', `Unknown live message (${m.keys.join(', ')})`);
        return;
    }
  }

  private updateSnapshot(): void {
    const s = this.store.getState();
    const model = s.statusModel;
    if (!model) {
      this.tracker.ok();
      return;
    }
    const now = this.ctx.now();
    const d = derive(model, s.status);
    if (d.fileName !== this.jobName) {
      this.jobName = d.fileName;
      this.jobStartedAt = d.fileName ? now : null;
    }
    const { activity, label } = activityOf(d, s.startup, s.exception);
    const alarms = alarmsOf(s.startup, s.exception, (id) => {
      if (!this.alarmSince.has(id)) this.alarmSince.set(id, now);
      return this.alarmSince.get(id) as number;
    });
    for (const id of [...this.alarmSince.keys()])
      if (!alarms.some((a) => a.id === id)) this.alarmSince.delete(id);
    this.history.push(now, d.series);
    this.tracker.ok({
      activity,
      activityLabel: label,
      job: jobOf(d, this.jobStartedAt, now),
      alarms,
      positions: d.positions,
      temperatures: d.temperatures,
      identity: `Prunt · ${s.api === 'module' ? 'module API' : 'flat API (2025)'}`,
    });
  }

  // --- Config ----------------------------------------------------------------------------------

  /** Open the editor: schema + values (once; again after a save or a server restart). */
  openConfig(): Promise<void> {
    const c = this.config.getState();
    if (c.phase === 'ready' || c.phase === 'loading') return Promise.resolve();
    return this.loadConfig(null);
  }

  async loadConfig(notice: string | null): Promise<void> {
    this.config.setState({ phase: 'loading', error: null });
    try {
      const { wire, text } = await this.client.configSchema();
      const form = buildForm(wire, text);
      let { model } = this.config.getState();
      const old = this.config.getState().form;
      if (!model || !old || old.form.key !== form.form.key) {
        model = new FormModel(form.form, {
          storage: this.drafts,
          storageKey: `shopdeck:prunt:${this.machine.id}:drafts`,
        });
        if (old && old.form.key !== form.form.key)
          notice = `${notice ?? ''} The configuration schema changed.`.trim();
      }
      this.config.setState({ form, model });
      const values = await this.client.configValues();
      const conflicts = model.setBase(readValues(form, values.Values));
      model.setServerErrors(placeErrors(form, values.Errors));
      if (conflicts.length)
        notice =
          `${notice ?? ''} ${conflicts.length} of your unsaved edits conflict with the controller's values.`.trim();
      this.config.setState({ phase: 'ready', notice });
    } catch (e) {
      this.config.setState({ phase: 'error', error: describeError(e) });
    }
  }

  private async save(commandId: string): Promise<string> {
    const { form, model } = this.config.getState();
    if (!form || !model) throw new Error('The configuration is not loaded');
    const changes = model.changes();
    if (changes.length === 0) throw new Error('Nothing to save');
    if (model.hasLocalErrors()) throw new Error('Fix the highlighted values first');
    const valueOf = (id: string) => model.value(id);
    const patch =
      form.api === 'flat' ? buildFlatPatch(form, changes, valueOf) : buildModulePatch(form, changes, valueOf);
    this.config.setState({ saving: true });
    try {
      const reply = await this.client.saveConfig(patch, { commandId });
      const placed = placeErrors(form, reply.Errors);
      const newBase = readValues(form, reply.Values);
      const schemaError = placed.some((p) => p.schemaError);
      // The server answers 200 even when it rejects: a schema error means nothing was saved.
      // Without the flat API's message prefix, "saved" means the values came back as sent.
      const applied = changes.filter((c) => {
        const n = newBase[c.id];
        return n !== undefined && valuesEqual(n, c.to);
      }).length;
      const saved = !schemaError && (applied > 0 || changes.length === 0);
      model.setBase(newBase);
      model.setServerErrors(placed);
      const at = this.ctx.now();
      if (!saved) {
        const message = `Nothing was saved: the controller rejected the change (${placed.length} error${placed.length === 1 ? '' : 's'} shown under the fields).`;
        this.config.setState({ lastSave: { at, saved: false, message } });
        throw new Error(message);
      }
      const message = placed.length
        ? `Saved ${applied} value${applied === 1 ? '' : 's'}; the controller reports ${placed.length} problem${placed.length === 1 ? '' : 's'} (shown under the fields).`
        : `Saved ${applied} value${applied === 1 ? '' : 's'}.`;
      this.config.setState({ lastSave: { at, saved: true, message }, offerReload: true });
      return message;
    } finally {
      this.config.setState({ saving: false });
    }
  }

  // --- Files -----------------------------------------------------------------------------------

  async refreshFiles(): Promise<void> {
    try {
      const files = await this.client.uploads();
      this.store.setState({ files, filesError: null });
    } catch (e) {
      this.store.setState({ filesError: describeError(e) });
    }
  }

  async refreshUpdateCheck(): Promise<void> {
    const api = this.store.getState().api;
    if (!api) return;
    try {
      this.store.setState({ update: { result: await this.client.updateCheck(api), error: null } });
    } catch (e) {
      this.store.setState({ update: { result: null, error: describeError(e) } });
    }
  }

  // --- Commands --------------------------------------------------------------------------------

  private running(): boolean {
    const a = this.ctx.snapshot.getState().activity;
    return a === 'running' || a === 'paused';
  }

  private declare(): PruntCommands {
    const startupDone = (): true | string => {
      const st = this.store.getState().startup;
      return st === null || st === 'Done' ? true : `The server is not ready (${st})`;
    };
    const pause: CommandDecl<void> = {
      id: 'prunt.pause',
      label: 'Pause',
      hazard: 'job',
      role: 'operator',
      confirm: false,
      available: (s) => (s.activity === 'running' ? true : 'Nothing is running'),
      perform: async (_a, c) => {
        await this.client.pause(c);
        return 'pause requested';
      },
    };
    const resume: CommandDecl<void> = {
      id: 'prunt.resume',
      label: 'Resume',
      hazard: 'job',
      role: 'operator',
      confirm: 'Resume? The machine starts moving again.',
      available: (s) => (s.activity === 'paused' ? true : 'Not paused'),
      perform: async (_a, c) => {
        await this.client.resume(c);
        return 'resume requested';
      },
    };
    const cancel: CommandDecl<void> = {
      id: 'prunt.cancel',
      label: 'Cancel file',
      hazard: 'stop',
      role: 'operator',
      confirm: 'Cancel the running file? It cannot be resumed.',
      available: (s) => {
        if (this.store.getState().api !== 'module') return 'This server has no cancel (flat API, 2025)';
        return s.activity === 'running' || s.activity === 'paused' ? true : 'Nothing is running';
      },
      perform: async (_a, c) => {
        await this.client.cancel(c);
        return 'cancel requested';
      },
    };
    const runFile: CommandDecl<string> = {
      id: 'prunt.runFile',
      label: 'Run file',
      hazard: 'job',
      role: 'operator',
      confirm: (name) => `Run ${name}? The machine will heat and move.`,
      available: () => {
        const ready = startupDone();
        if (ready !== true) return ready;
        return this.running() ? 'A file is already running' : true;
      },
      perform: async (name, c) => {
        await this.client.runFile(name, c);
        return `started ${name}`;
      },
    };
    const runCommand: CommandDecl<string> = {
      id: 'prunt.runCommand',
      label: 'Send G-code',
      hazard: 'motion',
      role: 'supervisor',
      confirm: false,
      perform: async (command, c) => {
        const seq = ++this.gcodeSeq;
        const entry: GcodeEntry = {
          seq,
          at: this.ctx.now(),
          command,
          id: null,
          state: 'sending',
          output: [],
        };
        this.store.setState((s) => ({ gcode: [...s.gcode, entry].slice(-200) }));
        const setEntry = (p: Partial<GcodeEntry>) =>
          this.store.setState((s) => ({ gcode: s.gcode.map((g) => (g.seq === seq ? { ...g, ...p } : g)) }));
        try {
          const id = await this.client.runCommand(command, c);
          setEntry({ id, state: id ? 'sent' : 'Completed' });
          return id ? `accepted (ID ${id})` : 'accepted';
        } catch (e) {
          setEntry({ state: 'error', output: [describeError(e)] });
          throw e;
        }
      },
    };
    const saveConfig: CommandDecl<void> = {
      id: 'prunt.saveConfig',
      label: 'Save configuration',
      hazard: 'adjust',
      role: 'supervisor',
      // The review dialog (every change, old → new) is the confirmation.
      confirm: false,
      available: () => {
        const c = this.config.getState();
        if (!c.model || c.phase !== 'ready') return 'The configuration is not loaded';
        if (c.saving) return 'Saving…';
        if (c.model.hasLocalErrors()) return 'Fix the invalid values first';
        if (c.model.changes().length === 0) return 'No changes to save';
        return true;
      },
      perform: (_a, c) => this.save(c.commandId),
    };
    const reloadServer: CommandDecl<void> = {
      id: 'prunt.reloadServer',
      label: 'Reload server',
      hazard: 'dangerous',
      role: 'supervisor',
      confirm:
        'Reload the Prunt server to apply the configuration? A running file stops and the controller restarts.',
      perform: async (_a, c) => {
        await this.client.reloadServer(c);
        this.config.setState({ offerReload: false });
        return 'server reloading';
      },
    };
    const allowFirmwareUpdate: CommandDecl<void> = {
      id: 'prunt.allowFirmwareUpdate',
      label: 'Allow firmware update',
      hazard: 'dangerous',
      role: 'supervisor',
      confirm:
        'Allow the server to flash new firmware to the board? Do not switch the machine off while it runs.',
      confirmTwice: true,
      available: () =>
        this.store.getState().startup === 'Update_Required' ? true : 'No firmware update is required',
      perform: async (_a, c) => {
        await this.client.allowFirmwareUpdate(c);
        return 'firmware update allowed';
      },
    };
    const upload: CommandDecl<{ name: string; body: Blob | string }> = {
      id: 'prunt.upload',
      label: 'Upload file',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      perform: async ({ name, body }, c) => {
        const total = typeof body === 'string' ? body.length : body.size;
        this.store.setState({ upload: { name, loaded: 0, total, error: null, done: false } });
        try {
          await this.client.upload(name, body, {
            commandId: c.commandId,
            onProgress: (p: UploadProgress) =>
              this.store.setState((s) => ({
                upload: s.upload ? { ...s.upload, loaded: p.loaded, total: p.total || s.upload.total } : null,
              })),
          });
          this.store.setState((s) => ({
            upload: s.upload ? { ...s.upload, loaded: s.upload.total, done: true } : null,
          }));
          void this.refreshFiles();
          return `uploaded ${name}`;
        } catch (e) {
          this.store.setState((s) => ({
            upload: s.upload ? { ...s.upload, error: describeError(e) } : null,
          }));
          throw e;
        }
      },
    };
    return {
      pause,
      resume,
      cancel,
      runFile,
      runCommand,
      saveConfig,
      reloadServer,
      allowFirmwareUpdate,
      upload,
    };
  }
}
