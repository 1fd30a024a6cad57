import type { IncomingMessage, ServerResponse } from 'node:http';
import type { JsonRecord, TemperatureDecl, TemperatureReading } from '../src/fleet/contract';
import type { MachinesService, Principal, UsersService } from './services';
import { decodeSegment, sendJson } from './http-util';

/**
 * The last minutes of every machine's temperatures, kept in the gateway's memory (nothing on
 * disk: a restart starts empty), so a chart opened now starts with what came before it
 * (`GET /api/machines/<id>/temperatures`). Sampled from what the gateway already reads (the
 * family's `watch.temperatures`: the watch's poll answers, its stream's frames, a model stream's
 * merged model), once a second per machine at most, never by a read of its own. A controller's
 * answer is untrusted: only finite numbers in a sane range are kept, a bounded number of sensors
 * with short, plain names, a bounded number of samples and bytes per machine.
 */

/** How long samples are kept (ms). */
export const TEMPERATURE_WINDOW_MS = 10 * 60_000;
/** One sample per machine at most this often (ms). */
export const TEMPERATURE_EVERY_MS = 1000;
/** A reading older than this is not sampled again (a stream that went quiet, a slow poll). */
export const TEMPERATURE_STALE_MS = 2500;
/** Samples kept per machine (the window at one a second, and a margin). */
export const MAX_TEMPERATURE_SAMPLES = 720;
/** Sensors kept per machine; readings of others are dropped. */
export const MAX_TEMPERATURE_SENSORS = 24;
/** Longest sensor name and key (characters). */
export const MAX_SENSOR_NAME = 40;
export const MAX_SENSOR_KEY = 80;
/** Bytes (as JSON) a machine's samples may hold; the oldest go first beyond it. */
export const MAX_TEMPERATURE_BYTES = 128 * 1024;
/** Readings outside this range (°C) are not temperatures anyone heats to: not kept. */
export const TEMPERATURE_MIN_C = -100;
export const TEMPERATURE_MAX_C = 1500;

export interface TemperatureSensor {
  key: string;
  name: string;
}

/** One machine's answer: samples are `[t, v0, v1, …]`, `t` in the gateway's clock, `vi` for `sensors[i]`. */
export interface TemperatureHistory {
  machine: string;
  now: number;
  windowMs: number;
  everyMs: number;
  sensors: TemperatureSensor[];
  samples: Array<Array<number | null>>;
}

/** Control characters, bidirectional overrides and the like: never in a name. */
// eslint-disable-next-line no-control-regex
const UNSAFE = /[\u0000-\u001f\u007f-\u009f\u200b-\u200f\u2028-\u202e\u2066-\u2069\ufeff]/g;

/** A controller's name made plain and short (the page shows it as text; it is escaped there too). */
export function plainName(raw: string, max: number): string {
  const s = raw.replace(UNSAFE, ' ').replace(/\s+/g, ' ').trim();
  return [...s].slice(0, max).join('');
}

/** A reading as kept: a finite number in range, rounded to 0.1 °C; anything else null. */
export function saneTemperature(v: unknown): number | null {
  if (typeof v !== 'number' || !Number.isFinite(v)) return null;
  if (v < TEMPERATURE_MIN_C || v > TEMPERATURE_MAX_C) return null;
  return Math.round(v * 10) / 10;
}

interface Sample {
  t: number;
  /** Values by sensor index (the machine's `sensors`). */
  v: Array<number | null>;
  bytes: number;
}

/** One machine's samples. */
export class TemperatureLog {
  readonly sensors: TemperatureSensor[] = [];
  private readonly index = new Map<string, number>();
  private samples: Sample[] = [];
  private bytes = 0;
  /** Readings of sensors beyond the bound (counted, not kept). */
  dropped = 0;

  constructor(private readonly scrub: (s: string) => string = (s) => s) {}

  get size(): number {
    return this.samples.length;
  }

  get heldBytes(): number {
    return this.bytes;
  }

  /** Adds one sample of `readings` at `t`; nothing when none of them is a sane number. */
  add(t: number, readings: readonly TemperatureReading[]): void {
    const v: Array<number | null> = new Array<number | null>(this.sensors.length).fill(null);
    let any = false;
    for (const r of readings) {
      if (typeof r.key !== 'string' || typeof r.name !== 'string') continue;
      const value = saneTemperature(r.value);
      const key = plainName(this.scrub(r.key), MAX_SENSOR_KEY);
      if (!key) continue;
      let i = this.index.get(key);
      if (i === undefined) {
        if (value === null) continue;
        if (this.sensors.length >= MAX_TEMPERATURE_SENSORS) {
          this.dropped++;
          continue;
        }
        i = this.sensors.length;
        this.index.set(key, i);
        this.sensors.push({ key, name: '' });
        v.push(null);
      }
      const sensor = this.sensors[i];
      // The newest name wins (a tool renamed); scrubbed of the machine's secrets, plain, short.
      if (sensor) sensor.name = plainName(this.scrub(r.name), MAX_SENSOR_NAME) || key;
      if (value !== null) {
        v[i] = value;
        any = true;
      }
    }
    if (!any) return;
    // In time order only (a poll's reading may be older than the model sampled last).
    const last = this.samples[this.samples.length - 1];
    if (last && t <= last.t) return;
    // Its size as JSON, about: "[t," and each value with its comma.
    const bytes = 16 + v.reduce<number>((n, x) => n + (x === null ? 5 : String(x).length + 1), 0);
    this.samples.push({ t, v, bytes });
    this.bytes += bytes;
    this.trim(t);
  }

  /** Drops what is older than the window, beyond the count, beyond the bytes. */
  trim(now: number): void {
    let cut = 0;
    let bytes = this.bytes;
    const from = now - TEMPERATURE_WINDOW_MS;
    while (
      cut < this.samples.length &&
      ((this.samples[cut]?.t ?? Infinity) <= from ||
        this.samples.length - cut > MAX_TEMPERATURE_SAMPLES ||
        bytes > MAX_TEMPERATURE_BYTES)
    ) {
      bytes -= this.samples[cut]?.bytes ?? 0;
      cut++;
    }
    if (cut > 0) {
      this.samples = this.samples.slice(cut);
      this.bytes = bytes;
    }
    if (this.samples.length === 0 && this.sensors.length > 0) {
      // Nothing left: sensors no machine reads any more are forgotten with it.
      this.sensors.length = 0;
      this.index.clear();
    }
  }

  /** Samples after `since` (the gateway's clock), within the window at `now`. */
  read(now: number, since: number | null): Pick<TemperatureHistory, 'sensors' | 'samples'> {
    this.trim(now);
    const from = Math.max(now - TEMPERATURE_WINDOW_MS, since ?? -Infinity);
    const samples = this.samples
      .filter((s) => s.t > from)
      .map((s) => [s.t, ...s.v, ...new Array<null>(this.sensors.length - s.v.length).fill(null)]);
    return { sensors: this.sensors.map((s) => ({ ...s })), samples };
  }
}

/** What one machine's sampler reads from (gateway.ts wires it to the watch). */
export interface TemperatureSource {
  /** The family's declaration (a getter: a Duet learns its API later). */
  decl(): TemperatureDecl | undefined;
  /** The watched model stream's merged model now, when one is open. */
  model?(): JsonRecord | null;
}

/** One machine's sampler: the newest reading it was given, sampled once a second. */
export class TemperatureSampler {
  private latest: { at: number; readings: TemperatureReading[] } | null = null;
  /** When the reading last sampled was given (each is sampled once). */
  private sampledAt: number | null = null;

  constructor(
    readonly log: TemperatureLog,
    private readonly source: TemperatureSource,
    private readonly now: () => number,
  ) {}

  /** An answer to the watch's poll. */
  polled(path: string, status: number, body: string): void {
    const d = this.source.decl();
    if (!d?.fromPoll) return;
    this.note(() => d.fromPoll?.(path, status, body) ?? null);
  }

  /** A frame of the watched stream. */
  frame(frame: string): void {
    const d = this.source.decl();
    if (!d?.fromFrame) return;
    this.note(() => d.fromFrame?.(frame) ?? null);
  }

  private note(read: () => TemperatureReading[] | null): void {
    let r: TemperatureReading[] | null = null;
    try {
      r = read();
    } catch {
      r = null;
    }
    if (Array.isArray(r)) this.latest = { at: this.now(), readings: r };
  }

  /**
   * One sample now: the model stream's merged model (current while its socket is open), else the
   * newest reading given, once, when it is not older than the stale limit (at its own time). A
   * quiet stream or a failed poll leaves a gap, never a copied value.
   */
  sample(): void {
    const t = this.now();
    const d = this.source.decl();
    const model = d?.fromModel ? (this.source.model?.() ?? null) : null;
    let readings: TemperatureReading[] | null = null;
    let at = t;
    if (model && d?.fromModel) {
      try {
        readings = d.fromModel(model);
      } catch {
        readings = null;
      }
    }
    const latest = this.latest;
    if (!readings && latest && latest.at !== this.sampledAt && t - latest.at <= TEMPERATURE_STALE_MS) {
      readings = latest.readings;
      at = latest.at;
      this.sampledAt = latest.at;
    }
    if (!readings) this.log.trim(t);
    else this.log.add(at, readings);
  }
}

/** Every machine's temperatures, and the one timer that samples them. */
export class TemperatureStore {
  private readonly logs = new Map<string, TemperatureLog>();
  private readonly samplers = new Map<string, TemperatureSampler>();
  private timer: ReturnType<typeof setInterval> | null = null;

  constructor(
    private readonly now: () => number,
    private readonly scrub: (s: string) => string,
  ) {}

  /** The sampler of a machine (one per machine: a second call gives the same one). */
  sampler(machine: string, source: TemperatureSource): TemperatureSampler {
    const have = this.samplers.get(machine);
    if (have) return have;
    const log = new TemperatureLog(this.scrub);
    this.logs.set(machine, log);
    const s = new TemperatureSampler(log, source, this.now);
    this.samplers.set(machine, s);
    return s;
  }

  start(): void {
    if (this.timer || this.samplers.size === 0) return;
    this.timer = setInterval(() => this.sampleAll(), TEMPERATURE_EVERY_MS);
    this.timer.unref?.();
  }

  sampleAll(): void {
    for (const s of this.samplers.values()) s.sample();
  }

  stop(): void {
    if (this.timer) clearInterval(this.timer);
    this.timer = null;
  }

  log(machine: string): TemperatureLog | undefined {
    return this.logs.get(machine);
  }

  /** A machine's answer (an empty one for a machine nothing is sampled of). */
  history(machine: string, since: number | null): TemperatureHistory {
    const t = this.now();
    const kept = this.logs.get(machine)?.read(t, since) ?? { sensors: [], samples: [] };
    return {
      machine,
      now: t,
      windowMs: TEMPERATURE_WINDOW_MS,
      everyMs: TEMPERATURE_EVERY_MS,
      ...kept,
    };
  }
}

export const TEMPERATURES_API_PATH = /^\/api\/machines\/(?<id>[^/]+)\/temperatures$/;

/**
 * `GET /api/machines/<id>/temperatures?since=<ms>`: any signed-in user with the machine in their
 * list (everyone in open mode); a machine that is not theirs answers 404 as one that does not
 * exist; no session 401; not GET 405 (both the route's declaration, routes/machines.ts); a
 * `since` that is not a whole number 400.
 */
export function createTemperaturesApi(
  ctx: Pick<MachinesService, 'byId'> & Pick<UsersService, 'mayUseMachine'>,
  store: TemperatureStore,
) {
  return function temperaturesApi(
    req: IncomingMessage,
    res: ServerResponse,
    url: URL,
    rawId: string,
    principal: Principal,
  ): void {
    req.resume();
    const id = decodeSegment(rawId);
    const m = ctx.byId.get(id);
    if (!m || !ctx.mayUseMachine(principal, m.id)) {
      sendJson(res, 404, { error: 'no such machine' });
      return;
    }
    const raw = url.searchParams.get('since');
    let since: number | null = null;
    if (raw !== null && raw !== '') {
      if (!/^\d{1,16}$/.test(raw)) {
        sendJson(res, 400, { error: 'since: a time in ms since the epoch (the `now` of an earlier answer)' });
        return;
      }
      since = Number(raw);
    }
    sendJson(res, 200, store.history(m.id, since));
  };
}
