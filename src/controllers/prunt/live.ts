import type { StoreApi } from 'zustand/vanilla';
import type { LinkTracker, SessionContext } from '../../fleet/contract';
import { protocolError } from '../../fleet/errors';
import type { History } from './history';
import type { PruntState } from './state';
import { activityOf, alarmsOf, derive, jobOf, normalizeFlat, type StatusValues } from './status';
import {
  startupSchema,
  wsMessageSchema,
  type FlatStatusValues,
  type ModuleStatusValues,
  type WsMessage,
} from './wire';

/**
 * What the live data means: one `/websocket/everything` frame (or a `GET /status/values` read
 * after a command) → the Prunt store, the chart history and the machine snapshot. No timers,
 * no sockets: the session calls it only while its run is current (the kernel drops frames and
 * answers that arrive after stop).
 */
export class PruntLive {
  private alarmSince = new Map<string, number>();
  private jobStartedAt: number | null = null;
  private jobName: string | null = null;

  constructor(
    private readonly ctx: SessionContext,
    private readonly store: StoreApi<PruntState>,
    private readonly history: History,
    private readonly tracker: LinkTracker,
    /** The server restarted (a new start time): refetch what depends on it. */
    private readonly restarted: () => void,
  ) {}

  /** One socket frame. */
  message(text: string): void {
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

  /** A `GET /status/values` answer: the values of a tick (the module API's has no Startup). */
  values(
    wire: { api: 'module'; values: ModuleStatusValues } | { api: 'flat'; values: FlatStatusValues },
  ): void {
    const startup = wire.api === 'flat' ? wire.values['Startup'] : undefined;
    const parsed = typeof startup === 'string' ? startupSchema.safeParse(startup) : null;
    this.tick(
      wire.api === 'flat' ? normalizeFlat(wire.values) : wire.values,
      parsed?.success ? { startup: parsed.data } : {},
    );
  }

  private handle(m: WsMessage): void {
    switch (m.type) {
      case 'start': {
        const before = this.store.getState().startTime;
        this.store.setState({ startTime: m.startTime });
        if (before !== null && before !== m.startTime) {
          this.ctx.log.info('controller', `Server restarted (start time ${m.startTime})`);
          this.history.clear();
          this.restarted();
        }
        return;
      }
      case 'tick':
        if (m.api === 'module')
          this.tick(m.values, { startup: m.startup, smartPlug: m.smartPlug, exception: m.exception });
        else this.tick(normalizeFlat(m.values), { startup: m.startup });
        return;
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

  private tick(
    status: StatusValues,
    extra: Partial<Pick<PruntState, 'startup' | 'smartPlug' | 'exception'>>,
  ): void {
    const prev = this.store.getState();
    this.store.setState({ ...extra, status, statusAt: this.ctx.now() });
    const next = this.store.getState();
    // Structural sharing keeps an equal exception's identity: a new object is a new exception.
    if (next.exception !== prev.exception && next.exception)
      this.ctx.log.add(
        next.exception.fatal ? 'error' : 'warning',
        'controller',
        `Server exception: ${next.exception.message.trim()}`,
      );
    if (next.startup !== prev.startup && next.startup)
      this.ctx.log.info('controller', `Startup: ${next.startup}`);
    this.updateSnapshot();
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
    // The chart's samples only while a page shows the machine's details (a fleet page of 20
    // Prunts would fill 10 minutes of samples it never draws: docs/performance.md, the heap).
    if (this.ctx.detail()) this.history.push(now, d.series);
    else if (this.history.t.length) this.history.clear();
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
}
