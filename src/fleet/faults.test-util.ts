import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, expect, vi } from 'vitest';
import { SimDropped, type SimSocket, type SimSocketHandler, type Simulator } from './sim';

/**
 * Tests only: a fault gate in front of a simulator, standing for the TCP fault proxy of issue 15
 * and the console server behind it. `fault` applies to every HTTP request from the moment it is
 * set; sockets stay open (`closeSockets()` closes them), and go silent with `silent`.
 *
 * - `gateway`: the console server's own 502 `{"error","gateway":true}` with `X-Shopdeck-Gateway`;
 * - `gateway-body`: the same body without the header, 504;
 * - `network`: no answer at all (a network error);
 * - `cut`: the simulator's answer cut after 20 bytes;
 * - `silent`: the request is held (connection accepted, nothing answered) until the fault ends,
 *   then answered, as the proxy delivers what it held once the network heals;
 * - `unauthorized`: the controller refuses the key (401, `body401`).
 */
export type Fault = 'none' | 'gateway' | 'gateway-body' | 'network' | 'cut' | 'silent' | 'unauthorized';

export class FaultGate implements Simulator {
  readonly kind: Simulator['kind'];
  fault: Fault = 'none';
  /** Requests that reached the gate, by path (without query). */
  readonly seen: string[] = [];
  body401: { status: number; body: string } = { status: 401, body: '' };
  private disposed = false;
  private readonly sockets = new Set<SimSocket>();

  constructor(readonly inner: Simulator) {
    this.kind = inner.kind;
  }

  async fetch(req: Request, path: string): Promise<Response> {
    this.seen.push(path.split('?')[0] ?? path);
    while (this.fault === 'silent' && !this.disposed) await new Promise((r) => setTimeout(r, 25));
    switch (this.fault) {
      case 'gateway':
        return new Response(
          JSON.stringify({
            error: 'cannot reach the controller: connect ECONNREFUSED 10.0.0.50:8080',
            gateway: true,
          }),
          { status: 502, headers: { 'Content-Type': 'application/json', 'X-Shopdeck-Gateway': 'error' } },
        );
      case 'gateway-body':
        return new Response(
          JSON.stringify({ error: 'the controller did not answer within 8 s', gateway: true }),
          {
            status: 504,
            headers: { 'Content-Type': 'application/json' },
          },
        );
      case 'network':
        throw new SimDropped();
      case 'unauthorized':
        return new Response(this.body401.body, {
          status: this.body401.status,
          headers: { 'Content-Type': 'application/json' },
        });
      case 'cut': {
        const r = await this.inner.fetch(req, path);
        const text = await r.text();
        return new Response(text.slice(0, 20), { status: r.status, headers: r.headers });
      }
      default:
        return this.inner.fetch(req, path);
    }
  }

  /**
   * Sockets pass through; while the fault is `silent` their frames (both ways) are held and
   * delivered in order once it ends, as the proxy does. Other faults leave open sockets alone.
   */
  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    if (!this.inner.socket) return null;
    const held: Array<() => void> = [];
    let pumping = false;
    const pass = (fn: () => void): void => {
      if (this.fault !== 'silent' && held.length === 0) {
        fn();
        return;
      }
      held.push(fn);
      if (pumping) return;
      pumping = true;
      const pump = (): void => {
        if (this.disposed) return;
        if (this.fault === 'silent') {
          setTimeout(pump, 25);
          return;
        }
        pumping = false;
        for (const f of held.splice(0)) f();
      };
      setTimeout(pump, 25);
    };
    const tracked: SimSocket = {
      send: (d) => pass(() => sock.send(d)),
      close: (code, reason) => {
        this.sockets.delete(tracked);
        sock.close(code, reason);
      },
    };
    const h = this.inner.socket(path, tracked);
    if (!h) return null;
    this.sockets.add(tracked);
    return {
      message: (d) => pass(() => h.message(d)),
      close: () => {
        this.sockets.delete(tracked);
        h.close();
      },
    };
  }

  closeSockets(code = 4000): void {
    for (const s of [...this.sockets]) s.close(code, 'simulated socket close');
  }

  dispose(): void {
    this.disposed = true;
    this.inner.dispose();
  }
}

/**
 * The fault tests' harness: an msw server for the simulators (unhandled requests fail), fake
 * timers and Date for each test (the sessions' clocks), and `cleanup` run after each test.
 */
export function faultHarness(): { server: ReturnType<typeof setupServer>; cleanup: Array<() => void> } {
  const server = setupServer();
  const cleanup: Array<() => void> = [];
  beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
  afterAll(() => server.close());
  beforeEach(() => {
    vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
  });
  afterEach(() => {
    for (const fn of cleanup.splice(0)) fn();
    vi.restoreAllMocks();
    server.resetHandlers();
    vi.useRealTimers();
  });
  return { server, cleanup };
}

/** Fake time goes on by `ms`, in 50 ms steps (answers and timers interleave as in real time). */
export async function advance(ms: number): Promise<void> {
  for (let t = 0; t < ms; t += 50) await vi.advanceTimersByTimeAsync(50);
}

/** Simulated ms until `cond` holds (fails past `maxMs`). */
export async function within(cond: () => boolean, maxMs: number): Promise<number> {
  let t = 0;
  while (!cond() && t <= maxMs) {
    await vi.advanceTimersByTimeAsync(50);
    t += 50;
  }
  expect(cond(), `not within ${maxMs} ms`).toBe(true);
  return t;
}
