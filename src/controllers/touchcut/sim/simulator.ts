import {
  jsonResponse,
  splitPath,
  type SimControl,
  type SimOptions,
  type Simulator,
} from '../../../fleet/sim';
import { TOUCHCUT_PRIVILEGES } from '../client';
import { defaultUsers, type SimUser } from '../sim-users';
import { MANUAL_EXAMPLE_API_KEY } from './data/manual';
import { Canvas } from './png';
import {
  addDays,
  daysIn,
  isoDate,
  PROGRAM_NAMES,
  simDay,
  SIM_TOOLS,
  type Day,
  type DayToolTotals,
} from './statsgen';

/**
 * A simulated Kinetic TouchCut 7 REST server (`/rest/v1/...`), built from the manual's reference
 * section only (no real capture exists). SIMULATED: every value here is invented where the manual
 * gives only a template; the state words (machineState "Running", stateName "Cutting", …) beyond
 * the manual's "Idle" are the simulator's guesses.
 *
 * What it does, as the manual says:
 * - users with privileges in groups; groups may carry an API key (`X-TouchCut-API-Key`);
 * - `POST auth` → JWT (`Authorization: Bearer` or the `__Secure-jwt` cookie), JWTs expire;
 *   when both are sent, the JWT takes precedence;
 * - every documented error body (1003, 1002, 100, 101, 102, 2000) and status (400, 401, 403,
 *   405, 500); `auth/change-password` only with a JWT, never with an API key;
 * - a cutting cycle moving along a path; stats for any date range; monitor with `fields`;
 *   programs and unloader (shapes invented: "interface subject to change");
 * - a PNG screenshot that changes at most once per second ("If a second request is made within a
 *   second of the previous request, the previous screenshot will be returned").
 */

export { defaultUsers, type SimUser } from '../sim-users';

export const SIM_WEB_ACCESS = 'Web Access';
const ALL_PRIVILEGES = [SIM_WEB_ACCESS, ...TOUCHCUT_PRIVILEGES];

export interface SimGroup {
  name: string;
  privileges: string[];
  apiKey: string | null;
}

/** Simulated API key of the "Monitor" group (what a gateway would hold for a demo machine). */
export const SIM_MONITOR_API_KEY = 'SIMULATED0TOUCHCUT0MONITOR0KEY00000000000';

export function defaultGroups(): SimGroup[] {
  return [
    { name: 'Administrator', privileges: [...ALL_PRIVILEGES], apiKey: null },
    // The manual's dialog ("Modify User Group: User") with its example key.
    {
      name: 'User',
      privileges: [
        SIM_WEB_ACCESS,
        'Monitor System',
        'Add Remove Tools',
        'Add Remove Materials',
        'Add Remove Tool Processes',
        'Modify General Settings Advanced',
        'Modify Tools Advanced',
        'Modify Tool Processes Advanced',
        'Modify Tuning',
        'Confirm Maintenance Done',
        'Modify Dross Bin Settings',
        'Modify Current User',
        'Modify General Settings',
      ],
      apiKey: MANUAL_EXAMPLE_API_KEY,
    },
    { name: 'Monitor', privileges: [SIM_WEB_ACCESS, 'Monitor System'], apiKey: SIM_MONITOR_API_KEY },
    // Web access but no "Monitor System": status works, monitor and screenshot answer 403.
    { name: 'Office', privileges: [SIM_WEB_ACCESS, 'Modify Current User'], apiKey: null },
    { name: 'Guest', privileges: [], apiKey: null },
  ];
}

/** JWT lifetime in the simulator (TouchCut's own lifetime is not documented). */
export const SIM_JWT_TTL_MS = 15 * 60_000;
/** How long the simulated application stays "not ready" after a simulated restart. */
export const SIM_RESTART_MS = 8_000;
/** Stats logging range ("weekly, monthly, yearly"): the simulator logs monthly. */
export const SIM_LOG_DAYS = 31;

const TABLE = { w: 3000, h: 1500 };
const FEED_MM_S = 40; // 2400 mm/min
const RAPID_MM_S = 300;
const PIERCE_S = 1.5;
const AUTO_START_S = 8;

interface Segment {
  kind: 'rapid' | 'pierce' | 'cut';
  from: [number, number];
  to: [number, number];
  dur: number;
}

/** Nest size of a program: 3×2 parts (about 3 minutes), or 4×3 for the demo job (about 6). */
function buildProgram(seed: number, nest: { cols: number; rows: number } = { cols: 3, rows: 2 }): Segment[] {
  const segs: Segment[] = [];
  let at: [number, number] = [0, 0];
  const { cols, rows } = nest;
  const w = 280 + (seed % 3) * 40;
  const h = 180 + (seed % 2) * 60;
  for (let r = 0; r < rows; r++) {
    for (let c = 0; c < cols; c++) {
      const x = 200 + c * (w + 150);
      const y = 200 + r * (h + 150);
      const start: [number, number] = [x, y];
      segs.push({ kind: 'rapid', from: at, to: start, dur: Math.hypot(x - at[0], y - at[1]) / RAPID_MM_S });
      segs.push({ kind: 'pierce', from: start, to: start, dur: PIERCE_S });
      const pts: Array<[number, number]> = [
        [x + w, y],
        [x + w, y + h],
        [x, y + h],
        [x, y],
      ];
      let p = start;
      for (const q of pts) {
        segs.push({ kind: 'cut', from: p, to: q, dur: Math.hypot(q[0] - p[0], q[1] - p[1]) / FEED_MM_S });
        p = q;
      }
      at = start;
    }
  }
  segs.push({ kind: 'rapid', from: at, to: [0, 0], dur: Math.hypot(at[0], at[1]) / RAPID_MM_S });
  return segs;
}

type Mode = 'idle' | 'running' | 'paused' | 'error' | 'complete';

interface LiveTotals {
  time: number;
  distance: number;
  starts: number;
  errors: number;
}

function b64url(s: string): string {
  const b = typeof btoa === 'function' ? btoa(s) : Buffer.from(s, 'binary').toString('base64');
  return b.replace(/=+$/, '').replace(/\+/g, '-').replace(/\//g, '_');
}

const empty = (status: number) => new Response(null, { status });
const tcError = (status: number, code: string, msg: string) =>
  jsonResponse({ code, msg }, status, 'application/json; charset=utf-8');
const ok = (body: unknown) => jsonResponse(body, 200, 'application/json; charset=utf-8');

export class TouchcutSimulator implements Simulator {
  readonly kind = 'touchcut' as const;
  readonly users: SimUser[] = defaultUsers();
  readonly groups: SimGroup[] = defaultGroups();
  /** Issued JWTs: token -> user and expiry. */
  readonly tokens = new Map<string, { user: string; exp: number }>();
  /** TouchCut's current units ("default"). */
  defaultUnits: 'metric' | 'imperial' = 'metric';
  notReadyUntil = 0;
  breakJwt = false;
  autoOperator = true;
  /**
   * Demo job (control `demo`): larger nests (12 parts, about six minutes at 100 % feed) that the
   * simulated operator restarts a few seconds after each one completes. Only the simulator's own
   * state changes: no request is sent, exactly like an operator pressing Start at the machine.
   */
  demoJob = false;
  /**
   * Demo stand-in for the gateway. A simulated machine has no secrets in the machines file, so
   * the gateway that answers it from this simulator adds no key; the simulator plays that part: a request with neither a JWT nor a key is treated as carrying the "Monitor"
   * group's key (as a gateway with a configured apiKey would send). The control "Revoke the
   * console's API key" turns this off to show the needs-login path. Off by default (tests).
   */
  gatewayKeyStandIn = false;
  /** JWT lifetime (tests shorten it). */
  jwtTtlMs = SIM_JWT_TTL_MS;

  mode: Mode = 'idle';
  programName = 'No Active Program';
  private program: Segment[] = [];
  private segIndex = 0;
  private segT = 0;
  private programCount = 0;
  private idleFor = 0;
  private feedOverride = 100;
  pos = { x: 0, y: 0, z: 25 };
  toolOn = false;
  private errorMsg: { key: string; msg: string } | null = null;
  private lastAdvance: number;
  private readonly timer: ReturnType<typeof setInterval>;
  /** Live accumulation since the simulator started, added to the machine totals. */
  readonly live: LiveTotals = { time: 0, distance: 0, starts: 0, errors: 0 };
  /** Unloader: parts dropped on pallet stations. */
  private unloaded: Array<{ time: number; program: string; part: number; station: number }> = [];
  private screenshotCache: { at: number; png: Uint8Array } | null = null;
  /** Count of PNGs drawn (for tests). */
  screenshotsDrawn = 0;
  readonly requests: Array<{ method: string; path: string; headers: Record<string, string> }> = [];
  private readonly now: () => number;
  private readonly name: string;

  constructor(opts: SimOptions) {
    this.now = opts.now ?? Date.now;
    this.name = opts.name;
    this.lastAdvance = this.now();
    this.timer = setInterval(() => this.advance(), opts.tickMs ?? 250);
  }

  dispose(): void {
    clearInterval(this.timer);
  }

  // ---- world ------------------------------------------------------------------------------

  startProgram(): void {
    this.advance();
    if (this.mode === 'running' || this.mode === 'paused' || this.mode === 'error') return;
    this.programCount++;
    this.program = buildProgram(this.programCount, this.demoJob ? { cols: 4, rows: 3 } : undefined);
    this.programName = `${PROGRAM_NAMES[this.programCount % PROGRAM_NAMES.length] ?? 'PART'}.nc`;
    this.segIndex = 0;
    this.segT = 0;
    this.mode = 'running';
  }

  pause(): void {
    this.advance();
    if (this.mode === 'running') {
      this.mode = 'paused';
      this.toolOn = false;
    }
  }

  resume(): void {
    this.advance();
    if (this.mode === 'paused') this.mode = 'running';
  }

  stop(): void {
    this.advance();
    if (this.mode === 'running' || this.mode === 'paused') {
      this.mode = 'idle';
      this.toolOn = false;
      this.idleFor = 0;
    }
  }

  fault(key = 'TorchCollision', msg = 'Torch collision detected'): void {
    this.advance();
    this.mode = 'error';
    this.toolOn = false;
    this.errorMsg = { key, msg };
    this.live.errors++;
  }

  clearFault(): void {
    this.advance();
    if (this.mode === 'error') {
      this.mode = 'paused';
      this.errorMsg = null;
    }
  }

  get progress(): number {
    if (this.mode === 'complete') return 100;
    if (this.program.length === 0 || this.mode === 'idle') return 0;
    const total = this.program.reduce((s, g) => s + g.dur, 0);
    const done = this.program.slice(0, this.segIndex).reduce((s, g) => s + g.dur, 0) + this.segT;
    return Math.min(100, (done / total) * 100);
  }

  get segment(): Segment | null {
    return this.mode === 'running' || this.mode === 'paused' || this.mode === 'error'
      ? (this.program[this.segIndex] ?? null)
      : null;
  }

  /** Moves the world to now. */
  advance(): void {
    const t = this.now();
    let dt = Math.max(0, (t - this.lastAdvance) / 1000);
    this.lastAdvance = t;
    if (this.mode !== 'running') {
      if ((this.mode === 'idle' || this.mode === 'complete') && this.autoOperator) {
        this.idleFor += dt;
        if (this.idleFor >= AUTO_START_S) {
          this.idleFor = 0;
          this.startProgram();
        }
      }
      return;
    }
    dt *= this.feedOverride / 100;
    while (dt > 0 && this.mode === 'running') {
      const seg = this.program[this.segIndex];
      if (!seg) {
        this.mode = 'complete';
        this.toolOn = false;
        this.idleFor = 0;
        this.pos = { x: 0, y: 0, z: 25 };
        return;
      }
      const left = seg.dur - this.segT;
      const step = Math.min(left, dt);
      if (seg.kind === 'pierce' && this.segT === 0 && step > 0) this.live.starts++;
      this.segT += step;
      dt -= step;
      const f = seg.dur > 0 ? this.segT / seg.dur : 1;
      this.pos.x = seg.from[0] + (seg.to[0] - seg.from[0]) * f;
      this.pos.y = seg.from[1] + (seg.to[1] - seg.from[1]) * f;
      this.pos.z = seg.kind === 'rapid' ? 25 : seg.kind === 'pierce' ? 4 : 1.5;
      this.toolOn = seg.kind !== 'rapid';
      if (seg.kind !== 'rapid') this.live.time += step;
      if (seg.kind === 'cut') this.live.distance += step * FEED_MM_S;
      if (this.segT >= seg.dur) {
        // A part is finished when its last contour side is done.
        const next = this.program[this.segIndex + 1];
        if (seg.kind === 'cut' && next && next.kind !== 'cut') {
          this.unloaded.push({
            time: this.now(),
            program: this.programName,
            part: this.unloaded.filter((u) => u.program === this.programName).length + 1,
            station: 1 + (this.unloaded.length % 2),
          });
          if (this.unloaded.length > 500) this.unloaded.shift();
        }
        this.segIndex++;
        this.segT = 0;
      }
    }
  }

  /**
   * Starts the demo job: a cutting program that runs for several minutes and, once complete, starts
   * again (automatic cycle start on). A held or faulted program is stopped and replaced; a running
   * one is left alone (the next cycles are demo-sized).
   */
  startDemo(): void {
    this.advance();
    this.demoJob = true;
    this.autoOperator = true;
    this.feedOverride = 100;
    if (this.mode === 'error') {
      this.errorMsg = null;
      this.mode = 'paused';
    }
    if (this.mode === 'paused') this.stop();
    if (this.mode !== 'running') this.startProgram();
  }

  expireAllTokens(): void {
    for (const [, t] of this.tokens) t.exp = 0;
  }

  restartApp(): void {
    this.notReadyUntil = this.now() + SIM_RESTART_MS;
  }

  controls(): SimControl[] {
    return [
      { id: 'demo', label: 'Start a demo job', run: () => this.startDemo() },
      { id: 'start', label: 'Cycle start (operator at the machine)', run: () => this.startProgram() },
      { id: 'pause', label: 'Feed hold', run: () => this.pause() },
      { id: 'resume', label: 'Resume', run: () => this.resume() },
      { id: 'stop', label: 'Stop program', run: () => this.stop() },
      { id: 'fault', label: 'Torch collision', run: () => this.fault() },
      { id: 'clear', label: 'Clear error', run: () => this.clearFault() },
      {
        id: 'auto',
        label: 'Toggle automatic cycle start',
        run: () => (this.autoOperator = !this.autoOperator),
      },
      { id: 'expire', label: 'Expire all user logins (JWT)', run: () => this.expireAllTokens() },
      { id: 'restart', label: 'Restart TouchCut (not ready for 8 s)', run: () => this.restartApp() },
      { id: 'jwt', label: 'Toggle JWT creation failure (2000)', run: () => (this.breakJwt = !this.breakJwt) },
      {
        id: 'revoke-key',
        label: "Revoke / restore the console's API key",
        run: () => (this.gatewayKeyStandIn = !this.gatewayKeyStandIn),
      },
    ];
  }

  // ---- auth ---------------------------------------------------------------------------------

  private issueToken(user: string): string {
    const iat = this.now();
    const exp = iat + this.jwtTtlMs;
    const header = b64url(JSON.stringify({ alg: 'HS256', typ: 'JWT' }));
    const payload = b64url(
      JSON.stringify({
        sub: user,
        iat: Math.floor(iat / 1000),
        exp: Math.floor(exp / 1000),
        jti: Math.random(),
      }),
    );
    const token = `${header}.${payload}.${b64url(`simulated-signature-${this.tokens.size}`)}`;
    this.tokens.set(token, { user, exp });
    return token;
  }

  private group(name: string): SimGroup | undefined {
    return this.groups.find((g) => g.name === name);
  }

  /**
   * Who is asking: a JWT (header or `__Secure-jwt` cookie) takes precedence over an API key. Null
   * means 401.
   */
  private principal(req: Request): { user: string | null; privileges: string[]; via: 'jwt' | 'key' } | null {
    const auth = req.headers.get('authorization') ?? '';
    const cookie = /(?:^|;\s*)__Secure-jwt=([^;]+)/.exec(req.headers.get('cookie') ?? '')?.[1];
    const jwt = /^Bearer\s+(.+)$/i.exec(auth)?.[1]?.trim() ?? cookie;
    if (jwt) {
      const t = this.tokens.get(jwt);
      if (!t || t.exp <= this.now()) return null;
      const u = this.users.find((x) => x.username === t.user);
      const g = u ? this.group(u.group) : undefined;
      return { user: t.user, privileges: g?.privileges ?? [], via: 'jwt' };
    }
    const key =
      req.headers.get('x-touchcut-api-key')?.trim() ||
      (this.gatewayKeyStandIn ? SIM_MONITOR_API_KEY : undefined);
    if (key) {
      const g = this.groups.find((x) => x.apiKey !== null && x.apiKey === key);
      if (!g) return null;
      return { user: null, privileges: g.privileges, via: 'key' };
    }
    return null;
  }

  private async params(req: Request, query: URLSearchParams): Promise<URLSearchParams> {
    const out = new URLSearchParams(query);
    const text = await req.text();
    if (!text.trim()) return out;
    if (text.trim().startsWith('{')) {
      try {
        for (const [k, v] of Object.entries(JSON.parse(text) as Record<string, unknown>)) {
          if (v !== null && v !== undefined) out.set(k, String(v));
        }
      } catch {
        /* not JSON: ignore */
      }
      return out;
    }
    for (const [k, v] of new URLSearchParams(text)) out.set(k, v);
    return out;
  }

  private async auth(req: Request, query: URLSearchParams): Promise<Response> {
    const p = await this.params(req, query);
    const username = p.get('username');
    const password = p.get('password');
    if (!username) return tcError(400, '1003', 'Required parameter missing: username');
    if (!password) return tcError(400, '1003', 'Required parameter missing: password');
    if (this.now() < this.notReadyUntil) return tcError(400, '100', 'Application not ready');
    const u = this.users.find((x) => x.username.toLowerCase() === username.toLowerCase());
    if (!u) return tcError(400, '101', 'Invalid Username');
    if (u.password !== password) return tcError(400, '102', 'Invalid Password');
    if (!this.group(u.group)?.privileges.includes(SIM_WEB_ACCESS)) return empty(401);
    if (this.breakJwt) return tcError(500, '2000', 'Error creating JWT');
    return ok({ success: 'true', token: this.issueToken(u.username) });
  }

  private async changePassword(req: Request, query: URLSearchParams): Promise<Response> {
    const who = this.principal(req);
    // "Some REST API requests are not available via API Keys, such as rest/v1/auth/change-password".
    if (!who || who.via !== 'jwt') return empty(401);
    const p = await this.params(req, query);
    const oldPw = p.get('old-password');
    const newPw = p.get('new-password');
    const confirm = p.get('confirm-password');
    if (!oldPw) return tcError(400, '1003', 'Required parameter missing: old-password');
    if (!newPw) return tcError(400, '1003', 'Required parameter missing: new-password');
    if (!confirm) return tcError(400, '1003', 'Required parameter missing: confirm-password');
    if (confirm !== newPw) return tcError(400, '1002', 'Invalid parameter: confirm-password');
    if (this.now() < this.notReadyUntil) return tcError(400, '100', 'Application not ready');
    const u = this.users.find((x) => x.username === who.user);
    if (!u) return tcError(400, '101', 'Invalid Username');
    if (!who.privileges.includes('Modify Current User')) return empty(403);
    if (u.password !== oldPw) return tcError(400, '102', 'Invalid Password');
    if (this.breakJwt) return tcError(500, '2000', 'Error creating JWT');
    u.password = newPw;
    return ok({ success: 'true', token: this.issueToken(u.username) });
  }

  // ---- HTTP ---------------------------------------------------------------------------------

  async fetch(req: Request, path: string): Promise<Response> {
    const { pathname, query } = splitPath(path);
    const headers: Record<string, string> = {};
    req.headers.forEach((v, k) => (headers[k] = v));
    this.requests.push({ method: req.method, path, headers });
    if (this.requests.length > 1000) this.requests.splice(0, 500);
    this.advance();
    const m = /^\/rest\/v1\/([a-z-]+)(\/[^?]*)?$/i.exec(pathname.replace(/\/+$/, ''));
    if (!m) return new Response('Not Found', { status: 404 });
    const resource = (m[1] ?? '').toLowerCase();
    const sub = m[2] ?? '';
    if (resource === 'auth') {
      if (sub === '' && req.method === 'POST') return this.auth(req, query);
      if (sub.toLowerCase() === '/change-password' && req.method === 'POST')
        return this.changePassword(req, query);
      return empty(405);
    }
    const known = ['machine-info', 'status', 'stats', 'monitor', 'programs', 'unloader', 'screenshot'];
    if (!known.includes(resource)) return new Response('Not Found', { status: 404 });
    // "405 (Method not allowed, sub method below status/ is invalid)"
    if (sub !== '' || req.method !== 'GET') return empty(405);
    if (resource === 'machine-info') return ok(this.machineInfo());
    const who = this.principal(req);
    if (!who || !who.privileges.includes(SIM_WEB_ACCESS)) return empty(401);
    const needsMonitor = resource === 'monitor' || resource === 'screenshot';
    if (needsMonitor && !who.privileges.includes('Monitor System')) return empty(403);
    const units = this.units(query.get('units'), who.user);
    switch (resource) {
      case 'status':
        return ok(this.status(units, who.user));
      case 'stats':
        return ok(this.stats(query, units));
      case 'monitor':
        return ok(this.monitor(query.get('fields'), units));
      case 'programs':
        return ok(this.programs(query, units));
      case 'unloader':
        return ok(this.unloader(query, units));
      default:
        return this.screenshot();
    }
  }

  private units(q: string | null, _user: string | null): 'metric' | 'imperial' {
    if (q === 'metric' || q === 'imperial') return q;
    return this.defaultUnits;
  }

  machineInfo(): unknown {
    return {
      programName: 'TouchCut',
      exePath: 'C:\\TouchCut7\\',
      exeName: 'TouchCut7.exe',
      exeVersion: '7.0.123 (simulated)',
      licensedTo: `${this.name} (simulated)`,
      primeCutInfo: 'PrimeCutNE (simulated)',
      registrationInfo: 'Simulated machine',
      contactInfo: {
        companyName: 'Simulated Kinetic service',
        postalAddr: '',
        streetAddr: '',
        countryName: '',
        phone: '',
        fax: '',
        email: '',
        webSite: '',
      },
      tools: [
        { toolType: 'Plasma', toolName: 'Plasma', position: 1 },
        { toolType: 'Marker', toolName: 'Marker', position: 2 },
        { toolType: 'Laser Pointer', toolName: 'Laser Pointer', position: 0 },
      ],
    };
  }

  status(units: 'metric' | 'imperial', user: string | null): Record<string, unknown> {
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const seg = this.segment;
    const stateName =
      this.mode === 'error'
        ? 'Error'
        : this.mode === 'paused'
          ? 'Paused'
          : this.mode === 'running'
            ? seg?.kind === 'pierce'
              ? 'Piercing'
              : seg?.kind === 'cut'
                ? 'Cutting'
                : 'Rapid Move'
            : this.mode === 'complete'
              ? 'Program Complete'
              : 'Idle';
    const machineState = {
      idle: 'Idle',
      complete: 'Idle',
      running: 'Running',
      paused: 'Paused',
      error: 'Error',
    }[this.mode];
    const programState = {
      idle: 'Idle',
      complete: 'Complete',
      running: 'Running',
      paused: 'Paused',
      error: 'Stopped',
    }[this.mode];
    const moving = this.mode === 'running';
    const feed = moving ? (seg?.kind === 'rapid' ? RAPID_MM_S : seg?.kind === 'cut' ? FEED_MM_S : 0) * 60 : 0;
    const msgs: Array<{ key: string; msg: string }> = [];
    if (this.errorMsg) msgs.push(this.errorMsg);
    if (this.mode === 'paused')
      msgs.push({ key: 'FeedHold', msg: 'Feed hold: press Start on the machine to resume' });
    const v = (x: number) => Math.round(x * k * 1000) / 1000;
    const pose = { vec: [v(this.pos.x), v(this.pos.y), v(this.pos.z)], rot: [0, 0, 0] };
    const lag = moving ? 0.02 : 0;
    return {
      currentUser: user ?? 'Operator',
      isHomed: true,
      machineState,
      programState,
      programOverride: this.feedOverride === 100 ? 'None' : 'Feed Override',
      stateName,
      toolIndex: this.toolOn || moving ? 1 : 0,
      toolName: this.mode === 'idle' ? 'Laser Pointer' : 'Plasma',
      toolOn: this.toolOn,
      spacedCarriages: [1],
      activeCarriages: [1],
      heightControlAuto: true,
      drossBinMode: 'Auto',
      programName: this.mode === 'idle' && this.programCount === 0 ? 'No Active Program' : this.programName,
      programProgress: Math.round(this.progress * 10) / 10,
      plateOrigin: { vec: [v(10), v(12), 0], rot: [0, 0, 0.3] },
      plateRotation: 0.3,
      material: 'MS-10.00 mm (0.394")',
      materialName: 'MS',
      materialThickness: units === 'imperial' ? 0.394 : 10,
      commandedPos: pose,
      actualPos: { vec: [v(this.pos.x - lag), v(this.pos.y + lag), v(this.pos.z)], rot: [0, 0, 0] },
      feedrate: Math.round(feed * k * 10) / 10,
      feedOverride: this.feedOverride,
      msgStatus: msgs,
      units,
    };
  }

  // ---- stats --------------------------------------------------------------------------------

  /** The logging range: [first, endBefore) — "automatically clipped to the available stats logging range". */
  logRange(): { first: string; endBefore: string } {
    const tomorrow = addDays(isoDate(this.now()), 1);
    return { first: addDays(tomorrow, -SIM_LOG_DAYS), endBefore: tomorrow };
  }

  /** Days served for a request, after clipping. */
  clippedDays(start: string | null, endBefore: string | null): string[] {
    const r = this.logRange();
    const valid = (d: string | null) =>
      d && /^\d{4}-\d{2}-\d{2}$/.test(d) && !Number.isNaN(Date.parse(d)) ? d : null;
    const s = valid(start) ?? r.first;
    const e = valid(endBefore) ?? r.endBefore;
    return daysIn(s < r.first ? r.first : s, e > r.endBefore ? r.endBefore : e);
  }

  /** Machine totals: a base from before the logging range, plus every logged day, plus live cutting. */
  machineTotals(): DayToolTotals[] {
    const r = this.logRange();
    const days = daysIn(r.first, r.endBefore).map(simDay);
    return SIM_TOOLS.map(({ tool, name }) => {
      const base =
        tool === 1
          ? { time: 3_600_000, distance: 90_000_000, starts: 120_000, errors: 310 }
          : { time: 0, distance: 0, starts: 0, errors: 0 };
      const sum = { ...base };
      for (const d of days)
        for (const s of d.sessions)
          for (const t of s.toolTotals)
            if (t.tool === tool) {
              sum.time += t.time;
              sum.distance += t.distance;
              sum.starts += t.starts;
              sum.errors += t.errors;
            }
      if (tool === 1) {
        sum.time += this.live.time;
        sum.distance += this.live.distance;
        sum.starts += this.live.starts;
        sum.errors += this.live.errors;
      }
      const round = {
        time: Math.round(sum.time),
        distance: Math.round(sum.distance),
        starts: sum.starts,
        errors: sum.errors,
      };
      return { tool, name, ...round, carriages: [{ carriage: 1, ...round }] };
    });
  }

  stats(query: URLSearchParams, units: 'metric' | 'imperial'): unknown {
    const condensed = ['true', '1'].includes((query.get('condensed') ?? '').toLowerCase());
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const L = (x: number) => Math.round(x * k * 100) / 100;
    const days: Day[] = this.clippedDays(query.get('start-date'), query.get('end-before-date')).map(simDay);
    const nonZero = (t: { time: number; distance: number; starts: number; errors: number }) =>
      t.time !== 0 || t.distance !== 0 || t.starts !== 0 || t.errors !== 0;
    const tools = (list: DayToolTotals[], lastReset?: string) =>
      list
        .filter((t) => !condensed || nonZero(t))
        .map((t) => ({
          ...t,
          distance: L(t.distance),
          ...(lastReset ? { lastReset } : {}),
          carriages: t.carriages
            .filter((c) => !condensed || nonZero(c))
            .map((c) => ({ ...c, distance: L(c.distance), ...(lastReset ? { lastReset } : {}) })),
        }));
    const machine = this.machineTotals();
    // Resettable totals: reset at the start of the logging range, so they equal the logged days.
    const r = this.logRange();
    const resettable = machine.map((t) => {
      const base =
        t.tool === 1
          ? { time: 3_600_000, distance: 90_000_000, starts: 120_000, errors: 310 }
          : { time: 0, distance: 0, starts: 0, errors: 0 };
      const v = {
        time: t.time - base.time,
        distance: t.distance - base.distance,
        starts: t.starts - base.starts,
        errors: t.errors - base.errors,
      };
      return { ...t, ...v, carriages: [{ carriage: 1, ...v }] };
    });
    return {
      machine: tools(machine),
      machineResettable: tools(resettable, `${r.first}T00:00:00`),
      days: days
        .map((d) => ({
          date: d.date,
          sessions: d.sessions
            .filter((s) => !condensed || s.activeTime > 0)
            .map((s) => ({ ...s, toolTotals: tools(s.toolTotals) })),
          programs: d.programs,
          errors: d.errors,
        }))
        .filter((d) => !condensed || d.sessions.length + d.programs.length + d.errors.length > 0),
      consumables: days
        .flatMap((d) => d.consumables)
        .filter((c) => !condensed || c.pierces + c.distance + c.time > 0)
        .map((c) => ({
          ...c,
          distance: L(c.distance),
          thickness: Math.round(c.thickness * k * 1000) / 1000,
        })),
      units,
    };
  }

  // ---- monitor ------------------------------------------------------------------------------

  monitor(fields: string | null, units: 'metric' | 'imperial'): unknown {
    const k = units === 'imperial' ? 1 / 25.4 : 1;
    const seg = this.segment;
    const moving = this.mode === 'running' && seg?.kind !== 'pierce';
    const dir = seg ? [seg.to[0] - seg.from[0], seg.to[1] - seg.from[1]] : [0, 0];
    const len = Math.hypot(dir[0] ?? 0, dir[1] ?? 0) || 1;
    const speed = moving ? (seg?.kind === 'rapid' ? RAPID_MM_S : FEED_MM_S) * 60 : 0;
    const t = this.now() / 1000;
    const axis = (
      name: string,
      index: number,
      pos: number,
      vel: number,
      max: number,
      torqueLimit: number,
    ) => {
      const err = moving ? 0.01 + 0.01 * Math.sin(t * 3 + index) : 0;
      return {
        name,
        address: `MC, ${name}`,
        index,
        unitType: 'utLength',
        speedUnitType: 'utFeed',
        scale: 1,
        errorCode: this.mode === 'error' && name === 'axisTorch' ? 4 : 0,
        commandedPos: Math.round(pos * k * 1000) / 1000,
        actualPos: Math.round((pos - err) * k * 1000) / 1000,
        posError: Math.round(err * k * 10000) / 10000,
        errorLimit: Math.round(1 * k * 1000) / 1000,
        actualVel: Math.round(Math.abs(vel) * k * 10) / 10,
        torque:
          Math.round(
            (moving && Math.abs(vel) > 0.001
              ? 35 + 20 * Math.abs(Math.sin(t + index))
              : 4 + Math.abs(Math.sin(t + index))) * 10,
          ) / 10,
        torqueLimit,
        isEnabled: true,
        isMoving: moving && Math.abs(vel) > 0.001,
        isPosErrorInputOn: false,
        isHomeInputOn: pos <= 0.5,
        isRevLimInputOn: false,
        isFwdLimInputOn: false,
        isRevSoftLimOn: pos <= 0,
        isFwdSoftLimOn: pos >= max,
        canMoveFwd: pos < max,
        canMoveRev: pos > 0,
        io: [],
      };
    };
    const axes = [
      axis('axisLong', 1, this.pos.x, (speed * (dir[0] ?? 0)) / len, TABLE.w, 150),
      axis('axisShort', 10, this.pos.y, (speed * (dir[1] ?? 0)) / len, TABLE.h, 180),
      axis('axisTorch', 20, this.pos.z, 0, 150, 120),
    ];
    const cutting = this.mode === 'running' && seg?.kind === 'cut';
    const io = {
      din: [
        { name: 'E-Stop OK', address: 'IO, 1', value: true },
        { name: 'Torch Collision', address: 'IO, 2', value: this.errorMsg?.key === 'TorchCollision' },
        { name: 'Arc OK', address: 'IO, 3', value: cutting },
        { name: 'Gas Pressure OK', address: 'IO, 4', value: true },
      ],
      dout: [
        { name: 'Plasma Start', address: 'IO, 17', value: this.toolOn },
        { name: 'Dross Bin Fan', address: 'IO, 18', value: this.mode === 'running' },
        { name: 'Marker Down', address: 'IO, 19', value: false },
      ],
      ain: [
        {
          name: 'Arc Voltage',
          address: 'AI, 1',
          scale: 50,
          value: cutting ? Math.round((128 + 2 * Math.sin(t * 5)) * 10) / 10 : 0,
          unitType: 'V',
        },
        {
          name: 'Gas Pressure',
          address: 'AI, 2',
          scale: 1,
          value: Math.round((6.2 + 0.1 * Math.sin(t)) * 100) / 100,
          unitType: 'bar',
        },
      ],
      aout: [{ name: 'THC Setpoint', address: 'AO, 1', scale: 50, value: cutting ? 128 : 0, unitType: 'V' }],
    };
    // `fields`: comma separated, `*` wildcard under a group ("axes.*", "io.din", "axes.axisLong").
    const want = (fields ?? '')
      .split(',')
      .map((f) => f.trim())
      .filter(Boolean);
    if (want.length === 0) return { io, axes, units };
    const pick = (group: string, name: string) =>
      want.some(
        (f) =>
          f === group ||
          f === `${group}.*` ||
          f === '*' ||
          f.toLowerCase() === `${group}.${name}`.toLowerCase(),
      );
    const ioOut: Record<string, unknown> = {};
    for (const [g, items] of Object.entries(io)) if (pick('io', g)) ioOut[g] = items;
    return {
      // The manual's example answers `"io": []` when no I/O was asked for.
      io: Object.keys(ioOut).length > 0 ? ioOut : [],
      axes: axes.filter((a) => pick('axes', a.name)),
      units,
    };
  }

  // ---- programs, unloader (shapes invented: "interface subject to change") -------------------

  programs(query: URLSearchParams, units: string): unknown {
    const all = PROGRAM_NAMES.map((n, i) => ({
      fileId: 1000 + i,
      name: `${n}.nc`,
      path: `C:\\Jobs\\${n}.nc`,
      parts: 6,
      status: `${n}.nc` === this.programName && this.mode !== 'idle' ? this.mode : 'loaded',
      progress: `${n}.nc` === this.programName ? Math.round(this.progress) : 0,
      modified: `${isoDate(this.now() - i * 86_400_000)}T07:${String(10 + i).padStart(2, '0')}:00`,
    }));
    const offset = Math.max(0, Number(query.get('offset') ?? 0) || 0);
    const limit = Math.max(1, Math.min(100, Number(query.get('limit') ?? 50) || 50));
    const onlyChanged = ['true', '1'].includes((query.get('onlyChangedData') ?? '').toLowerCase());
    const active = {
      fileId: all.find((p) => p.name === this.programName)?.fileId ?? null,
      name: this.programName,
      progress: Math.round(this.progress * 10) / 10,
    };
    if (onlyChanged) return { activeProgram: active, units };
    return {
      total: all.length,
      offset,
      limit,
      programs: all.slice(offset, offset + limit),
      activeProgram: active,
      units,
    };
  }

  unloader(query: URLSearchParams, units: string): unknown {
    const stations = [1, 2].map((s) => ({
      station: s,
      name: s === 1 ? 'Pallet A' : 'Pallet B',
      state: this.mode === 'running' && this.unloaded.at(-1)?.station === s ? 'Unloading' : 'Ready',
      parts: this.unloaded.filter((u) => u.station === s).length,
      capacity: 60,
    }));
    const out: Record<string, unknown> = { stations, units };
    if (['true', '1'].includes((query.get('history') ?? '').toLowerCase())) {
      const start = query.get('start-date');
      const end = query.get('end-before-date');
      out.history = this.unloaded
        .map((u) => ({
          time: new Date(u.time).toISOString(),
          program: u.program,
          part: u.part,
          station: u.station,
        }))
        .filter((u) => (!start || u.time.slice(0, 10) >= start) && (!end || u.time.slice(0, 10) < end));
    }
    return out;
  }

  // ---- screenshot ---------------------------------------------------------------------------

  screenshotPng(): Uint8Array {
    const t = this.now();
    if (this.screenshotCache && t - this.screenshotCache.at < 1000) return this.screenshotCache.png;
    const png = this.drawScreen(t);
    this.screenshotsDrawn++;
    this.screenshotCache = { at: t, png };
    return png;
  }

  private screenshot(): Response {
    const png = this.screenshotPng();
    return new Response(png.slice().buffer, {
      status: 200,
      headers: { 'Content-Type': 'image/png', 'Content-Length': String(png.length) },
    });
  }

  private drawScreen(t: number): Uint8Array {
    const W = 400;
    const H = 250;
    // 0 bg, 1 panel, 2 table, 3 cut, 4 torch, 5 text, 6 bad, 7 ok
    const c = new Canvas(W, H, [
      [18, 24, 32],
      [34, 44, 58],
      [120, 140, 160],
      [255, 170, 40],
      [80, 200, 255],
      [230, 235, 240],
      [230, 60, 60],
      [60, 200, 100],
    ]);
    c.fill(0, 0, W, 22, 1);
    const d = new Date(t);
    const hh = [d.getUTCHours(), d.getUTCMinutes(), d.getUTCSeconds()]
      .map((n) => String(n).padStart(2, '0'))
      .join(':');
    c.text(6, 6, `SIMULATED ${hh} UTC`, 5);
    const status = this.status('metric', null);
    c.text(
      6,
      H - 14,
      `${String(status.stateName)} ${Math.round(this.progress)}%`,
      this.mode === 'error' ? 6 : 7,
    );
    const sx = (W - 20) / TABLE.w;
    const sy = (H - 60) / TABLE.h;
    const s = Math.min(sx, sy);
    const ox = 10;
    const oy = 30;
    const X = (x: number) => ox + x * s;
    const Y = (y: number) => oy + (TABLE.h - y) * s;
    c.rect(X(0), Y(TABLE.h), TABLE.w * s, TABLE.h * s, 2);
    if (this.segment || this.mode === 'complete') {
      const upto = this.mode === 'complete' ? this.program.length : this.segIndex;
      for (let i = 0; i < this.program.length; i++) {
        const g = this.program[i];
        if (!g || g.kind !== 'cut') continue;
        if (i < upto) c.line(X(g.from[0]), Y(g.from[1]), X(g.to[0]), Y(g.to[1]), 3);
        else c.line(X(g.from[0]), Y(g.from[1]), X(g.to[0]), Y(g.to[1]), 1);
      }
      const g = this.program[this.segIndex];
      if (g && g.kind === 'cut' && this.mode !== 'complete')
        c.line(X(g.from[0]), Y(g.from[1]), X(this.pos.x), Y(this.pos.y), 3);
    }
    const tx = X(this.pos.x);
    const ty = Y(this.pos.y);
    const torch = this.toolOn ? 3 : 4;
    c.line(tx - 6, ty, tx + 6, ty, torch);
    c.line(tx, ty - 6, tx, ty + 6, torch);
    c.rect(tx - 3, ty - 3, 6, 6, torch);
    return c.toPng();
  }
}

/** The family's simulator factory (demo mode and `npm run sim`): plays the gateway's key too. */
export function createTouchcutSimulator(opts: SimOptions): TouchcutSimulator {
  const sim = new TouchcutSimulator(opts);
  sim.gatewayKeyStandIn = true;
  return sim;
}
