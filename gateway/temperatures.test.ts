import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { WebSocketServer } from 'ws';
import { duetFamily } from '../src/controllers/duet/family';
import { DuetSimulator } from '../src/controllers/duet/sim/simulator';
import { pruntFamily } from '../src/controllers/prunt/family';
import type { TemperatureReading } from '../src/fleet/contract';
import {
  MAX_SENSOR_NAME,
  MAX_TEMPERATURE_BYTES,
  MAX_TEMPERATURE_SAMPLES,
  MAX_TEMPERATURE_SENSORS,
  TEMPERATURE_EVERY_MS,
  TEMPERATURE_WINDOW_MS,
  TemperatureStore,
  type TemperatureHistory,
} from './temperatures';
import { type Cleanups, consoleFetch, gatewayFor, login, user } from './test-util';
import type { MachineEntry } from './machines';

/**
 * The last minutes of temperatures the gateway keeps for the charts (temperatures.ts), through
 * the real gateway on real sockets: sampled from the watch of simulated machines (Duet over DSF's
 * shared model socket, Prunt over its status socket), bounded against a hostile controller, and
 * served only to users with the machine.
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  vi.useRealTimers();
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function until<T>(what: string, get: () => Promise<T | null>, ms = 15_000): Promise<T> {
  const end = Date.now() + ms;
  for (;;) {
    const v = await get();
    if (v !== null) return v;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 50));
  }
}

const sim = (id: string, kind: 'duet' | 'prunt'): MachineEntry => ({
  id,
  name: `${kind} ${id}`,
  kind,
  simulated: true,
  url: null,
  wsUrl: null,
  secrets: {},
});

async function temps(base: string, id: string, cookie: string, query = ''): Promise<Response> {
  return consoleFetch(`${base}/api/machines/${encodeURIComponent(id)}/temperatures${query}`, {
    headers: { Cookie: cookie },
  });
}

describe('GET /api/machines/<id>/temperatures through the real gateway', () => {
  it('keeps the simulated Duet’s and Prunt’s temperatures from the watch; only users with the machine read them', async () => {
    const gw = await gatewayFor(cleanups, [sim('d1', 'duet'), sim('p1', 'prunt')], {
      families: {
        duet: { ...duetFamily, createSimulator: (o) => new DuetSimulator({ ...o, tickMs: 200 }) },
        prunt: pruntFamily,
      },
      users: [
        user('vic', 'viewer', 'vic-pass-1', { machines: ['d1'] }),
        user('sue', 'supervisor', 'sue-pass-1', { machines: ['p1'] }),
      ],
      watch: true,
    });
    const vic = await login(gw.url, 'vic', 'vic-pass-1');
    const sue = await login(gw.url, 'sue', 'sue-pass-1');
    const read = async (id: string, cookie: string): Promise<TemperatureHistory | null> => {
      const r = await temps(gw.url, id, cookie);
      expect(r.status).toBe(200);
      const h = (await r.json()) as TemperatureHistory;
      return h.samples.length >= 3 ? h : null;
    };
    // Nobody opened a page: the watch's reads alone fill it, one sample a second.
    const duet = await until('three Duet samples', () => read('d1', vic));
    expect(duet.sensors.map((s) => s.name)).toEqual(expect.arrayContaining(['Bed']));
    expect(duet.windowMs).toBe(TEMPERATURE_WINDOW_MS);
    for (const s of duet.samples) {
      expect(s).toHaveLength(duet.sensors.length + 1);
      expect(s[0]).toBeLessThanOrEqual(duet.now);
    }
    const bed = duet.sensors.findIndex((s) => s.name === 'Bed');
    expect(typeof duet.samples[0]?.[bed + 1]).toBe('number');
    // Times increase, at least a sample period apart (no duplicate point).
    for (let i = 1; i < duet.samples.length; i++)
      expect((duet.samples[i]?.[0] ?? 0) - (duet.samples[i - 1]?.[0] ?? 0)).toBeGreaterThanOrEqual(
        TEMPERATURE_EVERY_MS * 0.5,
      );
    const prunt = await until('three Prunt samples', () => read('p1', sue));
    expect(prunt.sensors.length).toBeGreaterThan(0);
    expect(prunt.sensors.every((s) => /temperat/i.test(s.key))).toBe(true);
    // `since`: only what came after an earlier answer's time.
    const later = (await (await temps(gw.url, 'd1', vic, `?since=${duet.now}`)).json()) as TemperatureHistory;
    expect(later.samples.every((s) => (s[0] ?? 0) > duet.now)).toBe(true);
    expect((await temps(gw.url, 'd1', vic, '?since=yesterday')).status).toBe(400);

    // Another user's machine answers as one that does not exist; no session, 401; reads only.
    const vicOther = await temps(gw.url, 'p1', vic);
    expect(vicOther.status).toBe(404);
    expect(JSON.stringify(await vicOther.json())).not.toMatch(/THERMISTOR|temperat/i);
    expect((await temps(gw.url, 'nope', vic)).status).toBe(404);
    expect((await temps(gw.url, 'd1', sue)).status).toBe(404);
    expect((await temps(gw.url, 'd1', '')).status).toBe(401);
    const post = await consoleFetch(`${gw.url}/api/machines/d1/temperatures`, {
      method: 'POST',
      headers: { Cookie: vic },
    });
    expect(post.status).toBe(405);
  }, 40_000);
});

/** A Prunt (flat API) stand-in whose status ticks are hostile: the gateway's watch listens to it. */
async function hostilePrunt(cleanups: Cleanups, tick: () => string): Promise<string> {
  const server = http.createServer((_req, res) => {
    res.writeHead(404);
    res.end();
  });
  const wss = new WebSocketServer({ server });
  const timers = new Set<ReturnType<typeof setInterval>>();
  wss.on('connection', (sock) => {
    sock.send(JSON.stringify({ Server_Start_Time: ' 1.0' }));
    const t = setInterval(() => sock.send(tick()), 100);
    timers.add(t);
    sock.on('close', () => clearInterval(t));
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  cleanups.push(async () => {
    for (const t of timers) clearInterval(t);
    for (const c of wss.clients) c.terminate();
    await new Promise<void>((r) => wss.close(() => r()));
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  });
  return `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
}

describe('a hostile controller’s temperatures', () => {
  it('keeps only sane finite numbers, a bounded number of sensors with short plain names, never a secret', async () => {
    const SECRET = 'sekrit-prunt-key-8841';
    const huge = `${'\u0007\u202e<img src=x onerror=alert(1)>'.repeat(5000)}${SECRET}`;
    const thermistors: Record<string, unknown> = {
      GOOD: 215.04,
      HOT_SUN: 1e308,
      COLD: -1e308,
      TOO_HOT: 99999,
      BELOW_ABSOLUTE: -500,
      WORDS: 'hot',
      OBJ: { a: 1 },
      NOTHING: null,
      [SECRET]: 60,
      [huge]: 40,
    };
    // Thousands of heaters: far past the bound.
    for (let i = 0; i < 3000; i++) thermistors[`T${i}`] = 20 + (i % 50);
    const tick = JSON.stringify({
      Status: {
        Time: 1,
        Thermistor_Temperatures: thermistors,
        Current_File_Name: '',
        Startup: 'Done',
      },
    });
    const url = await hostilePrunt(cleanups, () => tick);
    const gw = await gatewayFor(
      cleanups,
      [
        {
          id: 'px',
          name: 'Hostile',
          kind: 'prunt',
          simulated: false,
          url: new URL(url),
          wsUrl: null,
          secrets: { apiKey: SECRET },
        },
      ],
      { families: { prunt: pruntFamily }, watch: true },
    );
    const h = await until('three samples of the hostile Prunt', async () => {
      const r = await temps(gw.url, 'px', '');
      expect(r.status).toBe(200);
      const text = await r.text();
      // Bounded whatever the controller sends (the answer of 24 sensors is a few KB).
      expect(text.length).toBeLessThan(MAX_TEMPERATURE_BYTES + 8192);
      expect(text).not.toContain(SECRET);
      const j = JSON.parse(text) as TemperatureHistory;
      return j.samples.length >= 3 ? j : null;
    });
    expect(h.sensors.length).toBe(MAX_TEMPERATURE_SENSORS);
    for (const s of h.sensors) {
      expect([...s.name].length).toBeLessThanOrEqual(MAX_SENSOR_NAME);
      // eslint-disable-next-line no-control-regex
      expect(s.name + s.key).not.toMatch(/[\u0000-\u001f\u007f\u202e]/);
    }
    const names = h.sensors.map((s) => s.name);
    expect(names).toContain('GOOD');
    for (const bad of ['HOT_SUN', 'COLD', 'TOO_HOT', 'BELOW_ABSOLUTE', 'WORDS', 'OBJ', 'NOTHING'])
      expect(names).not.toContain(bad);
    for (const s of h.samples)
      for (const v of s.slice(1))
        if (v !== null) {
          expect(Number.isFinite(v)).toBe(true);
          expect(v).toBeGreaterThanOrEqual(-100);
          expect(v).toBeLessThanOrEqual(1500);
        }
    const good = names.indexOf('GOOD');
    expect(h.samples[0]?.[good + 1]).toBe(215);
  }, 30_000);
});

describe('the time window and the bounds (fake timers)', () => {
  it('keeps 10 minutes, one sample a second at most, never a copied reading, within count and bytes', () => {
    vi.useFakeTimers({ now: 1_700_000_000_000 });
    const store = new TemperatureStore(Date.now, (s) => s);
    let readings: TemperatureReading[] | null = null;
    const sampler = store.sampler('m', { decl: () => ({ fromFrame: () => readings }) });
    store.start();
    const sensors = (v: number): TemperatureReading[] =>
      Array.from({ length: 40 }, (_, i) => ({ key: `k${i}`, name: `Heater ${i}`, value: v + i / 3 }));
    // 15 minutes of frames, ten a second (a busy viewer's rate): sampled once a second.
    for (let s = 0; s < 15 * 60; s++) {
      for (let f = 0; f < 10; f++) {
        readings = sensors(100 + (s % 100));
        sampler.frame('tick');
        vi.advanceTimersByTime(100);
      }
    }
    const h = store.history('m', null);
    expect(h.samples.length).toBeLessThanOrEqual(MAX_TEMPERATURE_SAMPLES);
    expect(h.samples.length).toBeGreaterThanOrEqual(TEMPERATURE_WINDOW_MS / TEMPERATURE_EVERY_MS - 2);
    expect(h.samples[0]?.[0]).toBeGreaterThan(h.now - TEMPERATURE_WINDOW_MS);
    expect(h.sensors).toHaveLength(MAX_TEMPERATURE_SENSORS);
    expect(store.log('m')?.heldBytes).toBeLessThanOrEqual(MAX_TEMPERATURE_BYTES);
    expect(JSON.stringify(h).length).toBeLessThan(MAX_TEMPERATURE_BYTES + 4096);

    // The controller goes quiet: no new sample (its last reading is not copied on)…
    const before = store.history('m', null).samples.length;
    const lastT = store.history('m', null).samples.at(-1)?.[0] ?? 0;
    vi.advanceTimersByTime(30_000);
    const quiet = store.history('m', null);
    expect(quiet.samples.at(-1)?.[0]).toBe(lastT);
    expect(quiet.samples.length).toBeLessThanOrEqual(before);
    // …and after ten minutes of silence nothing is left, sensors included.
    vi.advanceTimersByTime(TEMPERATURE_WINDOW_MS);
    const gone = store.history('m', null);
    expect(gone.samples).toEqual([]);
    expect(gone.sensors).toEqual([]);
    store.stop();
  });
});
