import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { WebSocket as NodeWebSocket } from 'ws';
import type { MachineEntry } from '../../gateway/machines';
import { startSimServer, type SimServer } from '../../gateway/sim-server';
import { startGateway, tempDir, type Running } from '../../gateway/test-util';
import { STALE_MS } from '../../src/app/status';
import { loadController, MACHINE_KINDS } from '../../src/controllers';
import { DuetSimulator } from '../../src/controllers/duet/sim/simulator';
import { families } from '../../src/controllers/families';
import type { PruntSession } from '../../src/controllers/prunt/session';
import { loadBoard3 } from '../../src/controllers/prunt/sim/board';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from '../../src/controllers/touchcut/sim/simulator';
import type { MachineSession, SessionContext } from '../../src/fleet/contract';
import { createContext } from '../../src/fleet/fleet';
import { alwaysVisible } from '../../src/fleet/link';
import { apiOrigin, setApiOrigin } from '../../src/fleet/origin';
import type { Simulator } from '../../src/fleet/sim';
import type { LinkState, MachineKind } from '../../src/fleet/types';
import { startFaultProxy, type FaultMode, type FaultProxy } from './proxy';

/**
 * The fault matrix of issue 15, on real sockets: for each family, its simulator served as a real
 * controller (gateway/sim-server.ts) behind a TCP fault proxy (both of xTool's ports), the real
 * gateway in front of it, and the family's real browser session on the gateway's URL. A second
 * simulator of every family stands beside it, not behind any proxy. For each fault:
 *
 * - detected: the machine's link is no longer "online" (or its data is flagged stale) within 5 s;
 * - recovered: "online" with data newer than the end of the fault within 5 s of the fault ending,
 *   with the same session (never recreated for the case under test);
 * - the other machines keep updating throughout (online, data never older than their rhythm);
 * - no protocol or login verdict from a network fault, and no JSON dump as the problem's words;
 * - silent network: a pause sent at the start of the silence is reported as not confirmed, and
 *   never reaches the controller after the browser was told (requests counted at the simulator);
 * - Prunt: an unsaved config edit survives every case.
 *
 * Real timers, bounded waits; the families run side by side, the cases of a family one by one.
 * The bounds are wall-clock on a shared machine: a case that misses one gets one more run (a
 * fresh fault on the same session), and fails if it misses again; the summary marks a second run.
 */

const KINDS = ['touchcut', 'g2core', 'duet', 'xtool', 'prunt'] as const satisfies readonly MachineKind[];
type Kind = (typeof KINDS)[number];

/** Detection and recovery bounds of the issue. */
const DETECT_MS = 5000;
const RECOVER_MS = 5000;
/** How long a fault lasts (longer than DETECT_MS: detection is measured inside it). */
const HOLD_MS = 6000;
const DUET_PASSWORD = 'matrix-duet-pw';
const PRUNT_FIELD = 'Steppers$Steppers$STEPPER_1$Run current';

/**
 * How old a healthy machine's data may get before it counts as "not updating": the family's own
 * rhythm (TouchCut polls status every second, g2core status reports 4 per second, Duet patches,
 * Prunt ticks once a second, an xTool with a job polls every 3 s and reads frames) with slack.
 */
const FRESH_MS: Record<Kind, number> = {
  touchcut: 3000,
  g2core: 2000,
  duet: 4000,
  xtool: 12_000,
  prunt: 3000,
};

/** The pause of each family, and how the request looks when it reaches the controller. */
interface Seen {
  at: number;
  method: string;
  path: string;
  body: string;
}
const PAUSE: Partial<Record<Kind, { command: string; isPause: (s: Seen) => boolean }>> = {
  xtool: { command: 'xtool.pause', isPause: (s) => /[?&]action=pause\b/.test(s.path) },
  duet: {
    command: 'duet.pause',
    isPause: (s) => s.method === 'POST' && s.path.startsWith('/machine/code') && /^\s*M25\b/.test(s.body),
  },
  prunt: { command: 'prunt.pause', isPause: (s) => s.method === 'POST' && s.path.startsWith('/pause/pause') },
  g2core: { command: 'g2core.feedhold', isPause: (s) => s.method === 'PUT' && /"pause"/.test(s.body) },
  // TouchCut: the REST API is read-only for the machine (no pause to send).
};

// --- machines -------------------------------------------------------------------------------

interface Machine {
  kind: Kind;
  id: string;
  faulty: boolean;
  /** The family's simulator itself (not the recording or fault wrappers). */
  sim: Simulator;
  server: SimServer;
  /** Requests that reached the simulator. */
  seen: Seen[];
  /** The fault proxies in front of the simulator (HTTP port, and xTool's socket port). */
  proxies: FaultProxy[];
  ctx: SessionContext;
  session: MachineSession;
}

/** Records every request that reaches the simulator, with the time it arrived. */
function recording(inner: Simulator, seen: Seen[]): Simulator {
  return {
    kind: inner.kind,
    async fetch(req, p) {
      const body = req.method === 'GET' || req.method === 'HEAD' ? '' : await req.clone().text();
      seen.push({ at: Date.now(), method: req.method, path: p, body });
      return inner.fetch(req, p);
    },
    socket: inner.socket ? (p, sock) => inner.socket?.(p, sock) ?? null : undefined,
    controls: inner.controls ? () => inner.controls?.() ?? [] : undefined,
    dispose: () => inner.dispose(),
  };
}

function control(m: Machine, id: string): void {
  const c = m.sim.controls?.().find((x) => x.id === id);
  if (!c) throw new Error(`${m.id}: the simulator has no control "${id}"`);
  c.run();
}

async function startMachine(kind: Kind, faulty: boolean): Promise<Omit<Machine, 'ctx' | 'session'>> {
  const id = `${faulty ? 'f' : 'h'}-${kind}`;
  const sim = families[kind].createSimulator({ id, name: `${kind} ${faulty ? 'under faults' : 'healthy'}` });
  if (sim instanceof DuetSimulator) sim.password = DUET_PASSWORD;
  const seen: Seen[] = [];
  const server = await startSimServer({
    family: families[kind],
    id,
    name: id,
    simulator: recording(sim, seen),
  });
  const proxies: FaultProxy[] = [];
  if (faulty) {
    proxies.push(await startFaultProxy({ targetPort: Number(new URL(server.url).port) }));
    if (server.wsUrl) proxies.push(await startFaultProxy({ targetPort: Number(new URL(server.wsUrl).port) }));
  }
  return { kind, id, faulty, sim, server, seen, proxies };
}

function entryOf(m: Omit<Machine, 'ctx' | 'session'>): MachineEntry {
  const [http, ws] = m.proxies;
  const url = http ? http.url() : m.server.url;
  const wsUrl = ws ? ws.url('ws') : m.server.wsUrl;
  return {
    id: m.id,
    name: m.id,
    kind: m.kind,
    simulated: false,
    url: new URL(url),
    wsUrl: wsUrl ? new URL(wsUrl) : null,
    secrets:
      m.kind === 'touchcut'
        ? { apiKey: SIM_MONITOR_API_KEY }
        : m.kind === 'duet'
          ? { password: DUET_PASSWORD }
          : {},
  };
}

/** Every family's browser code (each is a chunk of its own in the page). */
const controllers = Object.fromEntries(
  await Promise.all(MACHINE_KINDS.map(async (k) => [k, await loadController(k)] as const)),
);

/** The family's real browser session, from its controller module, on a fresh context. */
function newSession(kind: Kind, id: string): { ctx: SessionContext; session: MachineSession } {
  const mod = controllers[kind];
  if (!mod) throw new Error(`no controller module for ${kind}`);
  const ctx = createContext(
    { id, name: id, kind, simulated: false },
    { visibility: alwaysVisible, principal: () => ({ name: 'matrix', role: 'supervisor' }) },
  );
  const session = mod.createSession(ctx);
  session.start();
  return { ctx, session };
}

const faulty = new Map<Kind, Machine>();
const healthy = new Map<Kind, Machine>();
let gateway: Running | null = null;
const restore: Array<() => Promise<void> | void> = [];

beforeAll(async () => {
  await loadBoard3();
  const started: Array<Omit<Machine, 'ctx' | 'session'>> = [];
  for (const kind of KINDS) {
    started.push(await startMachine(kind, true));
    started.push(await startMachine(kind, false));
  }
  restore.push(async () => {
    for (const m of started) {
      for (const p of m.proxies) await p.close();
      await m.server.close();
    }
  });
  const t = tempDir();
  restore.push(t.cleanup);
  gateway = await startGateway({
    machines: { file: null, machines: started.map(entryOf) },
    families,
    dataDir: t.dir,
    env: {},
  });
  const gw = gateway;
  restore.push(() => gw.close());
  // The page's origin is the gateway; its sockets send that Origin, as a browser does.
  const origin = apiOrigin();
  const previous = globalThis.WebSocket;
  const PageSocket = class extends NodeWebSocket {
    constructor(url: string | URL, protocols?: string | string[]) {
      super(url, protocols, { origin: gw.url });
    }
  };
  setApiOrigin(gw.url);
  (globalThis as { WebSocket?: unknown }).WebSocket = PageSocket;
  restore.push(() => {
    setApiOrigin(origin);
    (globalThis as { WebSocket?: unknown }).WebSocket = previous;
  });
  for (const s of started) {
    const m: Machine = { ...s, ...newSession(s.kind, s.id) };
    (m.faulty ? faulty : healthy).set(m.kind, m);
    // Work in progress everywhere: jobs make the machines talk (and give a pause something to do).
    control(m, 'demo');
  }
  restore.unshift(() => {
    for (const m of [...faulty.values(), ...healthy.values()]) m.session.stop();
  });
  // The machines beside the faulty ones are the yardstick: online before anything starts.
  for (const h of healthy.values())
    if (!(await waitFor(() => isFresh(h, Date.now() - FRESH_MS[h.kind]), 30_000)))
      throw new Error(`${h.id} never came online: ${JSON.stringify(h.ctx.snapshot.getState().problem)}`);
}, 90_000);

afterAll(async () => {
  for (const r of restore.splice(0).reverse()) await r();
  printSummary();
}, 30_000);

// --- observation -----------------------------------------------------------------------------

const sleep = (ms: number) => new Promise<void>((r) => setTimeout(r, ms));

async function waitFor(cond: () => boolean, ms: number, stepMs = 50): Promise<boolean> {
  const end = Date.now() + ms;
  for (;;) {
    if (cond()) return true;
    if (Date.now() >= end) return false;
    await sleep(stepMs);
  }
}

function isDown(m: Machine, now = Date.now()): boolean {
  const s = m.ctx.snapshot.getState();
  return s.link !== 'online' || (s.updatedAt !== null && now - s.updatedAt > STALE_MS);
}

function isFresh(m: Machine, since: number): boolean {
  const s = m.ctx.snapshot.getState();
  return s.link === 'online' && s.updatedAt !== null && s.updatedAt > since;
}

/** The oldest each healthy machine's data got over the whole run (printed with the summary). */
const worstAge = new Map<string, number>();

/** Samples every machine while a case runs. */
class Watch {
  readonly states = new Set<LinkState>();
  readonly problems = new Set<string>();
  /** Per healthy machine: the oldest its data got, and the link states it showed. */
  readonly others = new Map<string, { maxAgeMs: number; links: Set<LinkState>; limitMs: number }>();
  private timer: ReturnType<typeof setInterval>;

  constructor(private readonly m: Machine) {
    for (const h of healthy.values())
      this.others.set(h.id, { maxAgeMs: 0, links: new Set(), limitMs: FRESH_MS[h.kind] });
    this.timer = setInterval(() => this.sample(), 100);
    this.sample();
  }

  private sample(): void {
    const now = Date.now();
    const s = this.m.ctx.snapshot.getState();
    this.states.add(s.link);
    if (s.problem) this.problems.add(s.problem.message);
    for (const h of healthy.values()) {
      const o = this.others.get(h.id);
      const hs = h.ctx.snapshot.getState();
      if (!o) continue;
      o.links.add(hs.link);
      const age = hs.updatedAt === null ? Infinity : now - hs.updatedAt;
      o.maxAgeMs = Math.max(o.maxAgeMs, age);
      worstAge.set(h.id, Math.max(worstAge.get(h.id) ?? 0, age));
    }
  }

  stop(): void {
    clearInterval(this.timer);
    this.sample();
  }
}

// --- the cases -------------------------------------------------------------------------------

interface Fault {
  name: string;
  /** Which families have it (default all). */
  only?: readonly Kind[];
  /** Starts the fault. */
  apply: (m: Machine) => Promise<void>;
  /** Ends it (the proxies back to pass, the credentials back). */
  heal: (m: Machine) => Promise<void>;
  holdMs: number;
  /** false: a fault the link should ride through (latency): data keeps flowing instead. */
  detect: boolean;
  /** Its failures are a link problem, never a protocol or login verdict. */
  network: boolean;
  /** Send the family's pause at the start of the fault. */
  pause?: boolean;
}

const allProxies = (mode: FaultMode) => async (m: Machine) => {
  for (const p of m.proxies) await p.set(mode);
};
const pass = allProxies({ kind: 'pass' });

let revokedKey: string | null = null;

const FAULTS: Fault[] = [
  {
    name: 'controller refused',
    apply: allProxies({ kind: 'refuse' }),
    heal: pass,
    holdMs: HOLD_MS,
    detect: true,
    network: true,
  },
  {
    name: 'network silent (pause sent during the silence)',
    apply: allProxies({ kind: 'silent' }),
    heal: pass,
    holdMs: HOLD_MS,
    detect: true,
    network: true,
    pause: true,
  },
  {
    name: 'all connections reset',
    apply: allProxies({ kind: 'reset' }),
    heal: pass,
    holdMs: HOLD_MS,
    detect: true,
    network: true,
  },
  {
    name: '2 s latency each way',
    apply: allProxies({ kind: 'latency', ms: 2000 }),
    heal: pass,
    holdMs: 10_000,
    detect: false,
    network: true,
  },
  {
    name: 'controller restarted',
    apply: allProxies({ kind: 'restart', downMs: HOLD_MS }),
    heal: async (m) => {
      // The proxies pass again by themselves after downMs; make sure, without ending it early.
      for (const p of m.proxies) if (p.mode.kind !== 'pass') await p.set({ kind: 'pass' });
    },
    holdMs: HOLD_MS,
    detect: true,
    network: true,
  },
  {
    name: 'answers cut after 20 bytes',
    apply: allProxies({ kind: 'truncate', bytes: 20, then: 'close' }),
    heal: pass,
    holdMs: HOLD_MS,
    detect: true,
    network: true,
  },
  {
    name: 'API key refused for 5 s, then accepted',
    only: ['touchcut'],
    apply: async (m) => {
      if (!(m.sim instanceof TouchcutSimulator)) throw new Error('not a TouchCut simulator');
      const g = m.sim.groups.find((x) => x.apiKey === SIM_MONITOR_API_KEY);
      if (!g) throw new Error('no group holds the console key');
      revokedKey = g.apiKey;
      g.apiKey = 'REVOKED0BY0THE0FAULT0MATRIX000000000000000';
    },
    heal: async (m) => {
      if (!(m.sim instanceof TouchcutSimulator)) return;
      const g = m.sim.groups.find((x) => x.name === 'Monitor');
      if (g && revokedKey) g.apiKey = revokedKey;
    },
    holdMs: 5000,
    detect: true,
    network: false,
  },
  {
    name: 'password changed, then changed back',
    only: ['duet'],
    apply: async (m) => {
      if (!(m.sim instanceof DuetSimulator)) throw new Error('not a Duet simulator');
      m.sim.password = 'changed-by-the-fault-matrix';
      m.sim.expireSessions();
      m.sim.closeSockets(4000, 'password changed');
    },
    heal: async (m) => {
      if (m.sim instanceof DuetSimulator) m.sim.password = DUET_PASSWORD;
    },
    holdMs: 5000,
    detect: true,
    network: false,
  },
];

interface Result {
  kind: Kind;
  fault: string;
  detectedMs: number | null;
  detectedAs: string;
  recoveredMs: number | null;
  failures: string[];
  notes: string[];
}
const results: Result[] = [];

/** Before a case: the machine online with fresh data. A session a previous case left down is replaced (said in the notes). */
async function ensureOnline(m: Machine, notes: string[]): Promise<boolean> {
  for (const p of m.proxies) if (p.mode.kind !== 'pass') await p.set({ kind: 'pass' });
  const since = () => Date.now() - FRESH_MS[m.kind];
  if (await waitFor(() => isFresh(m, since()), 10_000)) return true;
  const s = m.ctx.snapshot.getState();
  notes.push(
    `session recreated before the case: the previous one stayed "${s.link}"${s.problem ? ` (${s.problem.message})` : ''}`,
  );
  m.session.stop();
  Object.assign(m, newSession(m.kind, m.id));
  return waitFor(() => isFresh(m, since()), 20_000);
}

async function pauseAvailable(m: Machine, command: string): Promise<string | null> {
  const cmd = m.session.commands[command];
  if (!cmd) return `the session declares no command ${command}`;
  const blocked = () => m.ctx.commands.blockedReason(cmd);
  if (await waitFor(() => blocked() === null, 8000)) return null;
  control(m, 'demo');
  if (await waitFor(() => blocked() === null, 10_000)) return null;
  return blocked();
}

function looksLikeJson(message: string): boolean {
  return /[{[]\s*"[^"]+"\s*:/.test(message);
}

async function runCase(m: Machine, f: Fault): Promise<Result> {
  const r: Result = {
    kind: m.kind,
    fault: f.name,
    detectedMs: null,
    detectedAs: '',
    recoveredMs: null,
    failures: [],
    notes: [],
  };
  if (!(await ensureOnline(m, r.notes))) {
    r.failures.push('the machine was not online before the fault (even with a new session)');
    return r;
  }
  const pauseDecl = f.pause ? PAUSE[m.kind] : undefined;
  if (f.pause && !pauseDecl) r.notes.push('no pause to send: the TouchCut REST API is read-only');
  if (pauseDecl) {
    const why = await pauseAvailable(m, pauseDecl.command);
    if (why) {
      r.failures.push(`setup: the pause is not available before the fault (${why})`);
      return r;
    }
  }
  const session = m.session;
  const ctx = m.ctx;
  const pausesBefore = m.seen.filter((s) => pauseDecl?.isPause(s)).length;
  const watch = new Watch(m);
  const t0 = Date.now();
  await f.apply(m);

  let told: { ok: boolean; message: string; at: number } | null = null;
  let sentAt = 0;
  if (pauseDecl) {
    const cmd = session.commands[pauseDecl.command];
    if (cmd) {
      sentAt = Date.now();
      void ctx.commands.run(cmd, undefined as never).then(
        (message) => (told = { ok: true, message, at: Date.now() }),
        (e: unknown) =>
          (told = { ok: false, message: e instanceof Error ? e.message : String(e), at: Date.now() }),
      );
    }
  }

  if (f.detect) {
    if (await waitFor(() => isDown(m), DETECT_MS)) {
      r.detectedMs = Date.now() - t0;
      const s = m.ctx.snapshot.getState();
      r.detectedAs = s.link === 'online' ? 'stale' : s.link;
    } else {
      const s = m.ctx.snapshot.getState();
      r.failures.push(
        `not detected within ${DETECT_MS / 1000} s: still "${s.link}", data ${s.updatedAt === null ? 'never' : `${Date.now() - s.updatedAt} ms old`}`,
      );
    }
  } else {
    // A slow link still delivers: fresh data arrives while the latency lasts.
    const through = t0 + 4000; // a request and its answer take at least 4 s
    if (await waitFor(() => isFresh(m, through), f.holdMs))
      r.notes.push(`data kept flowing (${Date.now() - t0} ms)`);
    else {
      const s = m.ctx.snapshot.getState();
      r.failures.push(
        `no data came through during ${f.holdMs / 1000} s of 2 s latency each way (link "${s.link}"${s.problem ? `: ${s.problem.message}` : ''})`,
      );
    }
  }

  // Hold the fault; with a pause in the air, until the browser was told (and a little more).
  const holdUntil = () => {
    const base = t0 + f.holdMs;
    if (!pauseDecl) return base;
    const t = told as { at: number } | null;
    return t ? Math.max(base, t.at + 1000) : t0 + 14_000;
  };
  await waitFor(() => Date.now() >= holdUntil(), 20_000, 25);
  await f.heal(m);
  const tEnd = Date.now();

  if (await waitFor(() => m.ctx === ctx && isFresh(m, tEnd), RECOVER_MS)) {
    r.recoveredMs = Date.now() - tEnd;
  } else {
    const s = ctx.snapshot.getState();
    r.failures.push(
      `not recovered within ${RECOVER_MS / 1000} s of the fault ending: "${s.link}"${s.problem ? ` (${s.problem.message})` : ''}`,
    );
  }

  if (pauseDecl) {
    // A pause held by the network would arrive now that it heals: give it the time to.
    await waitFor(() => Date.now() >= tEnd + 2500, 5000);
    const t = told as { ok: boolean; message: string; at: number } | null;
    const pauses = m.seen.filter((s) => pauseDecl.isPause(s)).slice(pausesBefore);
    if (!t)
      r.failures.push(
        'pause: the browser was never told what became of it (still in flight after the fault)',
      );
    else {
      r.notes.push(`pause told after ${t.at - sentAt} ms: ${t.ok ? 'ok' : 'failed'} "${t.message}"`);
      if (t.ok) r.failures.push(`pause reported as done ("${t.message}") although the network was silent`);
      else if (!/not confirmed/i.test(t.message))
        r.failures.push(
          `pause reported as "${t.message}", not as "not confirmed: it may or may not have reached the machine"`,
        );
      if (t.at - sentAt > 10_000)
        r.failures.push(
          `pause: the browser was told only after ${t.at - sentAt} ms (its deadline is a few seconds)`,
        );
      const late = pauses.filter((s) => s.at > t.at);
      if (late.length > 0)
        r.failures.push(
          `pause reached the controller ${late.map((s) => `${s.at - t.at} ms`).join(', ')} after the browser was told`,
        );
    }
    if (pauses.length > 1) r.failures.push(`pause reached the controller ${pauses.length} times`);
  }
  watch.stop();

  if (f.network) {
    const verdicts = [...watch.states].filter((s) => s === 'protocol-error' || s === 'needs-login');
    if (verdicts.length > 0)
      r.failures.push(
        `a network fault was shown as "${verdicts.join('", "')}" (${[...watch.problems].slice(0, 2).join(' | ')})`,
      );
  } else if (watch.states.has('protocol-error')) {
    r.failures.push(
      `an auth fault was shown as "protocol-error" (${[...watch.problems].slice(0, 2).join(' | ')})`,
    );
  }
  const dumps = [...watch.problems].filter(looksLikeJson);
  if (dumps.length > 0) r.failures.push(`the operator read JSON: ${dumps[0]?.slice(0, 160) ?? ''}`);

  for (const [id, o] of watch.others) {
    const bad = [...o.links].filter((l) => l !== 'online');
    if (bad.length > 0 || o.maxAgeMs > o.limitMs)
      r.failures.push(
        `other machine ${id} did not keep updating: ${bad.length ? `link ${bad.join('/')}` : ''} ${o.maxAgeMs > o.limitMs ? `data ${o.maxAgeMs} ms old (limit ${o.limitMs})` : ''}`.trim(),
      );
  }

  if (m.kind === 'prunt') {
    const model = (m.session as PruntSession).config.getState().model;
    const kept = model?.changes().some((c) => c.id === PRUNT_FIELD && String(c.to) === '2.5') ?? false;
    if (!kept) r.failures.push('the unsaved Prunt config edit was lost');
  }
  return r;
}

async function prepare(m: Machine): Promise<void> {
  if (!(await waitFor(() => isFresh(m, Date.now() - FRESH_MS[m.kind]), 20_000)))
    throw new Error(`${m.id} never came online: ${JSON.stringify(m.ctx.snapshot.getState().problem)}`);
  if (m.kind === 'prunt') {
    const s = m.session as PruntSession;
    await s.openConfig();
    const model = s.config.getState().model;
    if (!model) throw new Error('the Prunt config editor has no model');
    model.set(PRUNT_FIELD, '2.5');
  }
}

function printSummary(): void {
  if (results.length === 0) return;
  const lines = results.map(
    (r) =>
      `| ${r.kind} | ${r.fault} | ${r.detectedMs === null ? '—' : `${r.detectedMs} ms (${r.detectedAs})`} | ${r.recoveredMs === null ? '—' : `${r.recoveredMs} ms`} | ${r.failures.length === 0 ? 'pass' : `FAIL: ${r.failures.join('; ')}`} | ${r.notes.join('; ')} |`,
  );
  const ages = [...worstAge].map(([id, ms]) => `${id} ${ms} ms`).join(', ');
  console.log(
    [
      '| family | fault | detected | recovered | result | notes |',
      '|---|---|---|---|---|---|',
      ...lines,
      '',
      `Oldest data of the healthy machines during the cases: ${ages}`,
    ].join('\n'),
  );
}

describe('fault matrix (real sockets: simulator ← fault proxy ← gateway ← browser session)', () => {
  for (const kind of KINDS) {
    // The families side by side; the cases of one family one after another (one proxy, one session).
    describe(kind, { concurrent: true }, () => {
      describe.sequential('cases', () => {
        it('comes online through the proxy', async () => {
          const m = faulty.get(kind);
          if (!m) throw new Error('not started');
          await prepare(m);
        }, 30_000);
        for (const f of FAULTS) {
          if (f.only && !f.only.includes(kind)) continue;
          it(f.name, { timeout: 45_000, retry: 1 }, async ({ task }) => {
            const m = faulty.get(kind);
            if (!m) throw new Error('not started');
            const r = await runCase(m, f);
            if (task.result?.retryCount) r.notes.push('second run (the first missed a bound)');
            results.push(r);
            expect(r.failures, r.notes.join('; ')).toEqual([]);
          });
        }
      });
    });
  }
});
