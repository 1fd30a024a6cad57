import { splitPath, type SimControl, type SimOptions, type Simulator } from '../../../fleet/sim';
import { empty, ok, SIM_WEB_ACCESS } from './auth';
import { Canvas } from './png';
import { TouchcutSimReports } from './reports';
import { TABLE } from './world';

/**
 * A simulated Kinetic TouchCut 7 REST server (`/rest/v1/...`) from the manual's reference only (no
 * real capture): values and state words beyond the manual's are invented. It has every documented
 * error body and status; stats for any range, monitor with `fields`, programs and unloader (shapes
 * invented); a PNG screenshot that changes at most once a second. Layers: world.ts (the table),
 * auth.ts (users, groups, JWTs, API keys), reports.ts (read resources), this file (HTTP, screen).
 */

export { defaultUsers, type SimUser } from '../sim-users';
export {
  defaultGroups,
  SIM_JWT_TTL_MS,
  SIM_MONITOR_API_KEY,
  SIM_RESTART_MS,
  SIM_WEB_ACCESS,
  type SimGroup,
} from './auth';
export { SIM_LOG_DAYS } from './reports';

export class TouchcutSimulator extends TouchcutSimReports implements Simulator {
  readonly kind = 'touchcut' as const;
  private readonly timer: ReturnType<typeof setInterval>;
  private screenshotCache: { at: number; png: Uint8Array } | null = null;
  /** Count of PNGs drawn (for tests). */
  screenshotsDrawn = 0;
  readonly requests: Array<{ method: string; path: string; headers: Record<string, string> }> = [];

  constructor(opts: SimOptions) {
    super(opts);
    this.timer = setInterval(() => this.advance(), opts.tickMs ?? 250);
  }

  dispose(): void {
    clearInterval(this.timer);
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
