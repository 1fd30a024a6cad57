import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import type { AddressInfo } from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { WebSocket, WebSocketServer } from 'ws';
import bcrypt from 'bcryptjs';
import { operator, read, supervisor, type AccessPolicy } from '../src/fleet/access';
import type { FamilyDescriptor } from '../src/fleet/contract';
import { jsonResponse, splitPath, type Simulator } from '../src/fleet/sim';
import type { Role } from '../src/fleet/types';
import { createGateway, type Gateway, type GatewayOptions } from './gateway';
import type { MachineEntry } from './machines';
import type { UserRecord } from './users';

/** A self-signed certificate made with openssl in `dir` (files `<name>.key`/`<name>.pem`, and their text). */
export function selfSignedCert(
  dir: string,
  cn: string,
  name = cn,
  days = 1,
): { keyFile: string; certFile: string; key: string; cert: string } {
  const keyFile = path.join(dir, `${name}.key`);
  const certFile = path.join(dir, `${name}.pem`);
  execFileSync(
    'openssl',
    [
      'req',
      '-x509',
      '-newkey',
      'rsa:2048',
      '-nodes',
      '-keyout',
      keyFile,
      '-out',
      certFile,
      '-days',
      String(days),
      '-subj',
      `/CN=${cn}`,
    ],
    { stdio: 'ignore' },
  );
  return { keyFile, certFile, key: readFileSync(keyFile, 'utf8'), cert: readFileSync(certFile, 'utf8') };
}

/** Helpers for the gateway tests: temp folders, a stub controller, the gateway on a plain server. */

export function tempDir(): { dir: string; cleanup(): void } {
  const dir = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-gw-'));
  return { dir, cleanup: () => rmSync(dir, { recursive: true, force: true }) };
}

export function writeJson(file: string, data: unknown): string {
  writeFileSync(file, JSON.stringify(data, null, 2));
  return file;
}

export interface Seen {
  method: string;
  url: string;
  headers: http.IncomingHttpHeaders;
  body: string;
}

export interface Stub {
  url: string;
  wsUrl: string;
  port: number;
  seen: Seen[];
  wsSeen: Array<{ url: string; headers: http.IncomingHttpHeaders }>;
  /** Replace the answer: default `{ ok: true, path }` as JSON with a Set-Cookie. */
  respond: (req: IncomingMessage, res: ServerResponse, body: string) => void;
  close(): Promise<void>;
}

/** A controller stand-in that records what reaches it. WebSocket: echoes frames, prefixed "echo:". */
export async function startStub(
  tls?: { key: string; cert: string },
  opts: { greeting?: string } = {},
): Promise<Stub> {
  const seen: Seen[] = [];
  const wsSeen: Stub['wsSeen'] = [];
  const stub = { seen, wsSeen } as Stub;
  stub.respond = (req, res) => {
    const text = JSON.stringify({ ok: true, path: req.url });
    res.writeHead(200, { 'Content-Type': 'application/json', 'Set-Cookie': 'ctrl=1; Path=/' });
    res.end(text);
  };
  const handler = (req: IncomingMessage, res: ServerResponse): void => {
    const chunks: Buffer[] = [];
    req.on('data', (c: Buffer) => chunks.push(c));
    req.on('end', () => {
      const body = Buffer.concat(chunks).toString('utf8');
      seen.push({ method: req.method ?? '', url: req.url ?? '', headers: req.headers, body });
      stub.respond(req, res, body);
    });
  };
  const server = tls
    ? https.createServer({ key: tls.key, cert: tls.cert }, handler)
    : http.createServer(handler);
  const wss = new WebSocketServer({ server });
  wss.on('connection', (sock, req) => {
    wsSeen.push({ url: req.url ?? '', headers: req.headers });
    sock.send(opts.greeting ?? 'hello');
    sock.on('message', (d) => sock.send(`echo:${String(d)}`));
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  const port = (server.address() as AddressInfo).port;
  stub.port = port;
  stub.url = `${tls ? 'https' : 'http'}://127.0.0.1:${port}`;
  stub.wsUrl = `${tls ? 'wss' : 'ws'}://127.0.0.1:${port}`;
  stub.close = async () => {
    for (const c of wss.clients) c.terminate();
    await new Promise<void>((r) => wss.close(() => r()));
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  };
  return stub;
}

export interface Running {
  url: string;
  host: string;
  gw: Gateway;
  close(): Promise<void>;
}

/** A test file's cleanups: run after each test, newest first. */
export type Cleanups = Array<() => Promise<void> | void>;

/** A stub controller, closed by `cleanups`. */
export async function stubFor(cleanups: Cleanups): Promise<Stub> {
  const s = await startStub();
  cleanups.push(s.close);
  return s;
}

/** A machine of the test family (`prunt`) on the controller at `url` (a stub's; null: none). */
export function stubEntry(id: string, url: string | null, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id,
    name: id,
    kind: 'prunt',
    simulated: false,
    url: url === null ? null : new URL(url),
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

/**
 * The gateway with these machines, on the test family unless `families` says otherwise, its data
 * in a temporary folder; `users`: its users file (absent: open mode). Closed by `cleanups`.
 */
export async function gatewayFor(
  cleanups: Cleanups,
  machines: MachineEntry[],
  opts: { users?: UserRecord[] | null } & Partial<
    Omit<GatewayOptions, 'machines' | 'dataDir' | 'usersFile'>
  > = {},
): Promise<Running & { usersFile: string }> {
  const { users, ...rest } = opts;
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = path.join(t.dir, 'users.json');
  if (users) writeJson(usersFile, { users });
  const gw = await startGateway({
    families: { prunt: testFamily('prunt') },
    env: {},
    ...rest,
    machines: { file: null, machines },
    dataDir: t.dir,
    usersFile,
  });
  cleanups.push(gw.close);
  return { ...gw, usersFile };
}

/** The real middleware and upgrade listener on a plain Node server at 127.0.0.1:0. */
export async function startGateway(opts: GatewayOptions): Promise<Running> {
  // The watch's own reads would blur the requests tests count: on only where a test asks.
  const gw = createGateway({ watch: false, ...opts });
  const server = http.createServer((req, res) =>
    gw.handle(req, res, () => {
      res.writeHead(404, { 'Content-Type': 'text/plain' });
      res.end('not the gateway');
    }),
  );
  server.on('upgrade', (req, socket, head) => {
    if (!gw.upgrade(req, socket, head)) socket.destroy();
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  const port = (server.address() as AddressInfo).port;
  return {
    url: `http://127.0.0.1:${port}`,
    host: `127.0.0.1:${port}`,
    gw,
    close: async () => {
      gw.close();
      // As the server does at shutdown: what is queued reaches the file before the folder goes.
      await gw.audit.close().catch(() => undefined);
      await gw.alarms.close();
      server.closeAllConnections();
      await new Promise<void>((r) => server.close(() => r()));
    },
  };
}

/**
 * `fetch` as the console's own page sends it: with the `X-Shopdeck: 1` header that proves a
 * request comes from the console (csrf.ts). Attack tests use plain `fetch` instead.
 */
export function consoleFetch(url: string | URL, init: RequestInit = {}): Promise<Response> {
  const headers = new Headers(init.headers);
  if (!headers.has('x-shopdeck')) headers.set('X-Shopdeck', '1');
  return fetch(url, { ...init, headers });
}

/** Opens a WebSocket; resolves with the socket and its first message, or rejects with the HTTP status. */
export function openWs(
  url: string,
  headers: Record<string, string> = {},
  /** false: resolve as soon as it is open (`first` is ""): a controller may say nothing first. */
  waitFirst = true,
): Promise<{ ws: WebSocket; first: string; next(): Promise<string>; close(): Promise<void> }> {
  return new Promise((resolve, reject) => {
    // As a browser does: the page's origin (the gateway's own host) unless the test says otherwise.
    const origin = new URL(url.replace(/^ws/, 'http')).origin;
    const ws = new WebSocket(url, { headers: { Origin: origin, ...headers } });
    const queue: string[] = [];
    const waiters: Array<(s: string) => void> = [];
    ws.on('message', (d) => {
      const s = String(d);
      const w = waiters.shift();
      if (w) w(s);
      else queue.push(s);
    });
    const next = (): Promise<string> =>
      new Promise((r) => {
        const q = queue.shift();
        if (q !== undefined) r(q);
        else waiters.push(r);
      });
    ws.once('unexpected-response', (_req, res) => {
      const chunks: Buffer[] = [];
      res.on('data', (c: Buffer) => chunks.push(c));
      res.on('end', () => {
        ws.terminate();
        const err = new Error(
          `HTTP ${res.statusCode ?? 0}: ${Buffer.concat(chunks).toString('utf8')}`,
        ) as Error & {
          status?: number;
          body?: string;
        };
        err.status = res.statusCode;
        err.body = Buffer.concat(chunks).toString('utf8');
        reject(err);
      });
    });
    ws.once('error', (e) => reject(e));
    // Closed before its first frame: say so rather than wait for ever.
    ws.once('close', (code, reason) =>
      reject(Object.assign(new Error(`closed ${code} ${String(reason)} before a first frame`), { code })),
    );
    ws.once('open', () => {
      void (waitFirst ? next() : Promise.resolve('')).then((first) =>
        resolve({
          ws,
          first,
          next,
          close: () =>
            new Promise<void>((r) => {
              if (ws.readyState === WebSocket.CLOSED) r();
              else {
                ws.once('close', () => r());
                ws.close();
              }
            }),
        }),
      );
    });
  });
}

export function hashFast(secret: string): string {
  return bcrypt.hashSync(secret, 4);
}

export function user(
  name: string,
  role: Role,
  password: string,
  extra: Partial<UserRecord> = {},
): UserRecord {
  return { name, role, machines: null, passwordHash: hashFast(password), pinHash: null, ...extra };
}

/** Logs in; returns the cookie header to send. */
export async function login(base: string, name: string, password: string): Promise<string> {
  const r = await consoleFetch(`${base}/api/login`, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ name, password }),
  });
  if (r.status !== 200) throw new Error(`login ${name}: HTTP ${r.status} ${await r.text()}`);
  const c = r.headers.getSetCookie()[0] ?? '';
  return c.split(';')[0] ?? '';
}

/**
 * A family made for the tests (registered under whatever kind a test picks): reads, an
 * operator GET command, supervisor settings, a body-classified endpoint and two sockets.
 */
export const testAccess: AccessPolicy = (req) => {
  if (req.websocket)
    return req.path === '/console' ? supervisor('G-code console socket') : read('live status');
  if (req.method === 'GET' && req.path === '/status') return read();
  if (req.method === 'GET' && req.path === '/job') {
    const a = req.query.get('action');
    if (a === 'pause' || a === 'stop') return operator(`${a} the job`, `test.${a}`);
    return supervisor(`job action ${a ?? ''}`);
  }
  if (req.method === 'POST' && req.path === '/code') {
    return /^\s*M25\s*$/.test(req.body ?? '')
      ? operator('pause (M25)', 'test.pause')
      : supervisor('send G-code');
  }
  if (req.method === 'POST' && req.path === '/settings') return supervisor('change settings');
  if (req.method === 'GET' || req.method === 'HEAD') return read();
  return supervisor(`${req.method} ${req.path}`);
};

export function testSimulator(id: string): Simulator {
  let sockets = 0;
  return {
    kind: 'prunt',
    async fetch(req, p) {
      const { pathname, query } = splitPath(p);
      const body = req.method === 'GET' || req.method === 'HEAD' ? '' : await req.text();
      if (pathname === '/missing') return new Response('nope', { status: 404 });
      return jsonResponse({ sim: id, method: req.method, path: pathname, action: query.get('action'), body });
    },
    socket(p, sock) {
      if (p.startsWith('/none')) return null;
      sockets++;
      sock.send(`sim-hello ${sockets}`);
      return { message: (d) => sock.send(`sim-echo:${d}`), close: () => undefined };
    },
    controls: () => [{ id: 'button', label: 'Press the button', run: () => undefined }],
    dispose: () => undefined,
  };
}

export function testFamily(
  kind: FamilyDescriptor['kind'] = 'prunt',
  defaultWsPort?: number,
): FamilyDescriptor {
  return {
    kind,
    label: 'Test family',
    access: testAccess,
    accessNeedsBody: (method, p) => method === 'POST' && p === '/code',
    gateway: {
      defaultWsPort,
      // Its sockets are bridged one to one (the five families share theirs: streams.test.ts).
      bridgedSockets: { matches: () => true, maxPerMachine: 8 },
      injectSecrets(req, secrets) {
        if (secrets.apiKey) req.headers['X-Api-Key'] = secrets.apiKey;
        if (secrets.password && req.path === '/login') req.query.set('password', secrets.password);
      },
    },
    createSimulator: (o) => testSimulator(o.id),
  };
}
