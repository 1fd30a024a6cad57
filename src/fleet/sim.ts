import type { MachineApi, MachineKind } from './types';

/**
 * The simulator contract. One implementation per family feeds the gateway (simulated machines,
 * gateway/context.ts `simulatorFor`), the Node server of `npm run sim` and msw in tests; never
 * the browser's production bundle. A simulator speaks the controller's own protocol:
 * paths, status codes, error bodies and quirks as the protocol document and fixtures say.
 *
 * Everything is simulated: the UI and the docs say so wherever a simulator answers.
 */

export interface SimSocket {
  send(data: string): void;
  close(code?: number, reason?: string): void;
}

export interface SimSocketHandler {
  /** A frame from the client. */
  message(data: string): void;
  /** The client went away. */
  close(): void;
}

/** A button of the developer panel: stands in for the physical world (the machine's button, a flame). */
export interface SimControl {
  id: string;
  label: string;
  run(): void;
}

export interface Simulator {
  readonly kind: MachineKind;
  /**
   * Answer one HTTP request. `path` is the controller path with its query string, without the
   * `/machines/<id>` prefix ("/progress", "/system?action=version").
   */
  fetch(req: Request, path: string): Promise<Response>;
  /** Accept a WebSocket at `path` (with query), or return null: no socket there. */
  socket?(path: string, sock: SimSocket): SimSocketHandler | null;
  /** Controls for the developer panel and tests. */
  controls?(): SimControl[];
  /** Stop timers. */
  dispose(): void;
}

export interface SimOptions {
  id: string;
  name: string;
  /** The machines file's `api`, where a family simulates more than one (Duet: `standalone`). */
  machineApi?: MachineApi;
  /** Injectable clock for tests (defaults to Date.now). */
  now?: () => number;
  /** Time steps: the simulator advances its world every `tickMs` (default per family). */
  tickMs?: number;
}

export type SimulatorFactory = (opts: SimOptions) => Simulator;

export interface Faults {
  /** Extra latency on every HTTP answer (ms). */
  latencyMs: number;
  /** Drop HTTP requests (network error) and refuse sockets. */
  drop: boolean;
  /** Answer every HTTP request with 503. */
  http5xx: boolean;
  /** Answer every HTTP request with a truncated, malformed body. */
  malformed: boolean;
}

export const NO_FAULTS: Faults = { latencyMs: 0, drop: false, http5xx: false, malformed: false };

/** Thrown by a faulty simulator's fetch when `drop` is on: the transport turns it into a network error. */
export class SimDropped extends Error {
  constructor() {
    super('simulated dropped connection');
  }
}

/**
 * Wraps a simulator with fault injection. `closeSockets()` closes every open socket (code 1006
 * is not sendable, so 4000 "simulated socket close").
 */
export class FaultySimulator implements Simulator {
  faults: Faults = { ...NO_FAULTS };
  private sockets = new Set<SimSocket>();
  readonly kind: MachineKind;

  constructor(readonly inner: Simulator) {
    this.kind = inner.kind;
  }

  setFaults(f: Partial<Faults>): void {
    this.faults = { ...this.faults, ...f };
  }

  async fetch(req: Request, path: string): Promise<Response> {
    const f = this.faults;
    if (f.latencyMs > 0) await new Promise((r) => setTimeout(r, f.latencyMs));
    if (f.drop) throw new SimDropped();
    if (f.http5xx) return new Response('Service Unavailable (simulated fault)', { status: 503 });
    const res = await this.inner.fetch(req, path);
    if (f.malformed) {
      const text = await res.text();
      return new Response(text.slice(0, Math.max(1, Math.floor(text.length / 2))) + '\u0000{', {
        status: res.status,
        headers: res.headers,
      });
    }
    return res;
  }

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    if (this.faults.drop || !this.inner.socket) return null;
    const tracked: SimSocket = {
      send: (d) => sock.send(d),
      close: (code, reason) => {
        this.sockets.delete(tracked);
        sock.close(code, reason);
      },
    };
    const h = this.inner.socket(path, tracked);
    if (!h) return null;
    this.sockets.add(tracked);
    return {
      message: (d) => h.message(d),
      close: () => {
        this.sockets.delete(tracked);
        h.close();
      },
    };
  }

  closeSockets(): void {
    for (const s of [...this.sockets]) s.close(4000, 'simulated socket close');
  }

  controls(): SimControl[] {
    return this.inner.controls?.() ?? [];
  }

  dispose(): void {
    this.inner.dispose();
  }
}

/** JSON response helper for simulators: `contentType: null` sends no JSON content type (xTool). */
export function jsonResponse(
  body: unknown,
  status = 200,
  contentType: string | null = 'application/json',
): Response {
  const headers: Record<string, string> = {};
  if (contentType) headers['Content-Type'] = contentType;
  return new Response(JSON.stringify(body), { status, headers });
}

export function textResponse(body: string, status = 200, contentType = 'text/plain'): Response {
  return new Response(body, { status, headers: { 'Content-Type': contentType } });
}

/** Splits "/a/b?x=1" into path and query. */
export function splitPath(path: string): { pathname: string; query: URLSearchParams } {
  const i = path.indexOf('?');
  return i < 0
    ? { pathname: path, query: new URLSearchParams() }
    : { pathname: path.slice(0, i), query: new URLSearchParams(path.slice(i + 1)) };
}
