/**
 * Helpers of gateway.bench.ts: a closed-loop HTTP load (N keep-alive connections, each sending
 * its next GET as soon as the last one is answered), percentiles, and the server child process
 * (found by the port it listens on): its CPU time, resident memory, and, when it runs with
 * `--inspect`, its memory after a full garbage collection (Chrome DevTools Protocol).
 */
import http from 'node:http';
import { readdirSync, readFileSync, readlinkSync } from 'node:fs';
import { WebSocket } from 'ws';

export interface LoadOptions {
  /** Requests go to these URLs in turn (round-robin over every connection). */
  urls: string[];
  connections: number;
  /** Counted time. */
  seconds: number;
  /** Time before counting starts (connections made, code warmed); not counted. */
  warmupSeconds: number;
}

export interface LoadResult {
  /** Requests started and answered within the counted time. */
  requests: number;
  /** Every request sent, warm-up included. */
  sent: number;
  /** Failed requests (network errors, timeouts, statuses other than 2xx) in the counted time. */
  errors: number;
  /** The first failure, for the log. */
  firstError: string | null;
  seconds: number;
  /** Latency of each counted request, ms. */
  latencies: number[];
}

interface Target {
  host: string;
  port: number;
  path: string;
}

function toTarget(u: string): Target {
  const url = new URL(u);
  return { host: url.hostname, port: Number(url.port || 80), path: url.pathname + url.search };
}

const REQUEST_TIMEOUT_MS = 10_000;

/** One GET, its body read and dropped; resolves with the status. */
export function get(
  t: Target | string,
  agent: http.Agent,
  headers: http.OutgoingHttpHeaders = {},
): Promise<number> {
  const target = typeof t === 'string' ? toTarget(t) : t;
  return new Promise((resolve, reject) => {
    const req = http.get({ ...target, agent, headers }, (res) => {
      res.on('data', () => undefined);
      res.on('end', () => resolve(res.statusCode ?? 0));
      res.on('error', reject);
    });
    req.on('error', reject);
    req.setTimeout(REQUEST_TIMEOUT_MS, () => req.destroy(new Error('timed out')));
  });
}

/** A closed-loop load: `connections` requests in flight at all times, for warm-up plus `seconds`. */
export async function runLoad(o: LoadOptions): Promise<LoadResult> {
  const targets = o.urls.map(toTarget);
  if (targets.length === 0) throw new Error('runLoad: no URL');
  const agent = new http.Agent({ keepAlive: true, maxSockets: o.connections });
  const latencies: number[] = [];
  let errors = 0;
  let firstError: string | null = null;
  let next = 0;
  let sent = 0;
  const start = performance.now();
  const countFrom = start + o.warmupSeconds * 1000;
  const end = countFrom + o.seconds * 1000;
  const worker = async (): Promise<void> => {
    while (performance.now() < end) {
      const t = targets[next++ % targets.length] as Target;
      const t0 = performance.now();
      sent++;
      let failure: string | null = null;
      try {
        const status = await get(t, agent);
        if (status < 200 || status > 299) failure = `${t.path}: HTTP ${status}`;
      } catch (e) {
        failure = `${t.path}: ${e instanceof Error ? e.message : String(e)}`;
      }
      if (t0 < countFrom || t0 >= end) continue;
      if (failure) {
        errors++;
        firstError ??= failure;
      } else latencies.push(performance.now() - t0);
    }
  };
  try {
    await Promise.all(Array.from({ length: o.connections }, worker));
  } finally {
    agent.destroy();
  }
  return { requests: latencies.length, sent, errors, firstError, seconds: o.seconds, latencies };
}

/** The p-th percentile (0–100, nearest rank) of `xs`. */
export function percentile(xs: readonly number[], p: number): number {
  if (xs.length === 0) return Number.NaN;
  const s = [...xs].sort((a, b) => a - b);
  const i = Math.min(s.length - 1, Math.max(0, Math.ceil((p / 100) * s.length) - 1));
  return s[i] as number;
}

// ---------------------------------------------------------------- the server's memory

/** Listening TCP sockets (IPv4 and IPv6): inode → port. */
function listening(): Map<string, number> {
  const out = new Map<string, number>();
  for (const f of ['/proc/net/tcp', '/proc/net/tcp6']) {
    let text: string;
    try {
      text = readFileSync(f, 'utf8');
    } catch {
      continue;
    }
    for (const line of text.split('\n').slice(1)) {
      const cols = line.trim().split(/\s+/);
      // sl local_address rem_address st tx:rx tr:when retrnsmt uid timeout inode
      const port = cols[1]?.split(':')[1];
      if (port && cols[3] === '0A' && cols[9]) out.set(cols[9], parseInt(port, 16));
    }
  }
  return out;
}

/** Inodes of the sockets listening on `port`. */
function listeningInodes(port: number): Set<string> {
  return new Set([...listening()].filter(([, p]) => p === port).map(([inode]) => inode));
}

/** Inodes of the sockets `pid` has open. */
function socketInodes(pid: number): Set<string> {
  const out = new Set<string>();
  let fds: string[];
  try {
    fds = readdirSync(`/proc/${pid}/fd`);
  } catch {
    return out;
  }
  for (const fd of fds) {
    try {
      const m = /^socket:\[(\d+)\]$/.exec(readlinkSync(`/proc/${pid}/fd/${fd}`));
      if (m) out.add(m[1] as string);
    } catch {
      /* closed meanwhile */
    }
  }
  return out;
}

/** The TCP ports `pid` listens on. */
export function listeningPortsOf(pid: number): number[] {
  const mine = socketInodes(pid);
  return [...listening()].filter(([inode]) => mine.has(inode)).map(([, port]) => port);
}

/** The parent pid of `pid` (null when it is gone). */
function parentOf(pid: number): number | null {
  try {
    const stat = readFileSync(`/proc/${pid}/stat`, 'utf8');
    // pid (comm) state ppid …; comm may hold spaces and parentheses.
    const after = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
    return Number(after[1]);
  } catch {
    return null;
  }
}

/**
 * The pid of the child of `parent` that listens on `port` (Linux /proc): the benchmarks' server
 * is a child process whose pid the harness does not give.
 */
export function childListeningOn(port: number, parent = process.pid): number {
  const inodes = listeningInodes(port);
  if (inodes.size === 0) throw new Error(`nothing listens on port ${port}`);
  for (const name of readdirSync('/proc')) {
    if (!/^\d+$/.test(name)) continue;
    const pid = Number(name);
    if (parentOf(pid) !== parent) continue;
    for (const inode of socketInodes(pid)) if (inodes.has(inode)) return pid;
  }
  throw new Error(`no child process of ${parent} listens on port ${port}`);
}

/** CPU time `pid` has used, user + system, seconds (Linux clock ticks of 1/100 s). */
export function cpuSeconds(pid: number): number {
  const stat = readFileSync(`/proc/${pid}/stat`, 'utf8');
  // After "pid (comm) ": state is field 3, utime 14 and stime 15.
  const f = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
  return (Number(f[11]) + Number(f[12])) / 100;
}

/** Resident memory of `pid`, bytes (VmRSS). */
export function rssBytes(pid: number): number {
  const status = readFileSync(`/proc/${pid}/status`, 'utf8');
  const m = /^VmRSS:\s+(\d+)\s+kB/m.exec(status);
  if (!m) throw new Error(`no VmRSS for process ${pid}`);
  return Number(m[1]) * 1024;
}

// ---------------------------------------------------------------- the inspector

/** A Chrome DevTools Protocol session with a Node process started with `--inspect`. */
export class Inspector {
  private next = 1;
  private readonly waiting = new Map<number, { ok: (v: unknown) => void; fail: (e: Error) => void }>();

  private constructor(private readonly ws: WebSocket) {
    ws.on('message', (data) => {
      const msg = JSON.parse(String(data)) as { id?: number; result?: unknown; error?: { message?: string } };
      const w = msg.id === undefined ? undefined : this.waiting.get(msg.id);
      if (!w || msg.id === undefined) return;
      this.waiting.delete(msg.id);
      if (msg.error) w.fail(new Error(msg.error.message ?? 'inspector error'));
      else w.ok(msg.result);
    });
    ws.on('close', () => {
      for (const w of this.waiting.values()) w.fail(new Error('the inspector closed'));
      this.waiting.clear();
    });
  }

  /** Connects to the inspector of `pid`: the port it listens on besides `serverPort`. */
  static async of(pid: number, serverPort: number): Promise<Inspector> {
    const ports = listeningPortsOf(pid).filter((p) => p !== serverPort);
    for (const port of ports) {
      let list: Array<{ webSocketDebuggerUrl?: string }>;
      try {
        const res = await fetch(`http://127.0.0.1:${port}/json/list`);
        list = (await res.json()) as Array<{ webSocketDebuggerUrl?: string }>;
      } catch {
        continue;
      }
      const url = list[0]?.webSocketDebuggerUrl;
      if (!url) continue;
      const ws = new WebSocket(url, { perMessageDeflate: false });
      await new Promise<void>((resolve, reject) => {
        ws.once('open', () => resolve());
        ws.once('error', reject);
      });
      ws.on('error', () => undefined);
      return new Inspector(ws);
    }
    throw new Error(`process ${pid} has no inspector (start it with --inspect)`);
  }

  call(method: string, params: Record<string, unknown> = {}): Promise<unknown> {
    const id = this.next++;
    return new Promise((ok, fail) => {
      this.waiting.set(id, { ok, fail });
      this.ws.send(JSON.stringify({ id, method, params }));
    });
  }

  /** `process.memoryUsage()` of the process after two full garbage collections. */
  async memoryAfterGc(): Promise<NodeJS.MemoryUsage> {
    await this.call('HeapProfiler.collectGarbage');
    await this.call('HeapProfiler.collectGarbage');
    const r = (await this.call('Runtime.evaluate', {
      expression: 'JSON.stringify(process.memoryUsage())',
      returnByValue: true,
    })) as { result?: { value?: unknown } };
    if (typeof r.result?.value !== 'string') throw new Error('process.memoryUsage() gave nothing');
    return JSON.parse(r.result.value) as NodeJS.MemoryUsage;
  }

  close(): void {
    this.ws.terminate();
  }
}
