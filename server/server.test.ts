import { spawn, type ChildProcess } from 'node:child_process';
import { X509Certificate } from 'node:crypto';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import http, { type IncomingHttpHeaders } from 'node:http';
import https from 'node:https';
import type { TLSSocket } from 'node:tls';
import os from 'node:os';
import path from 'node:path';
import Database from 'better-sqlite3';
import { pathToFileURL } from 'node:url';
import { brotliDecompressSync, gunzipSync } from 'node:zlib';
import bcrypt from 'bcryptjs';
import { WebSocket } from 'ws';
import { afterAll, afterEach, beforeAll, describe, expect, it } from 'vitest';
import { compressDist } from './compress';
import { IMMUTABLE } from './server';

/**
 * The server as `npm start` runs it: a child process (`node --import tsx server/main.ts`) on a
 * free port, with a temporary data folder and a tiny built console made here.
 */

const root = path.resolve(import.meta.dirname, '..');
const tsxLoader = pathToFileURL(path.join(root, 'node_modules', 'tsx', 'dist', 'loader.mjs')).href;
const mainTs = path.join(root, 'server', 'main.ts');

const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-server-'));
const dist = path.join(work, 'dist');
const APP = 'assets/app-abc123.js';
const appSource =
  '// Shopdeck test bundle\n' +
  Array.from({ length: 200 }, (_, i) => `export const value${i} = 'line ${i} of the console';\n`).join('');
const INDEX =
  '<!doctype html><html><head><meta charset="utf-8"><title>Shopdeck test</title>' +
  `<script type="module" src="/${APP}"></script></head><body><div id="root"></div></body></html>\n`;

beforeAll(async () => {
  mkdirSync(path.join(dist, 'assets'), { recursive: true });
  writeFileSync(path.join(dist, 'index.html'), INDEX);
  writeFileSync(path.join(dist, APP), appSource);
  writeFileSync(path.join(dist, `${APP}.map`), JSON.stringify({ version: 3, sources: ['secret.ts'] }));
  const first = await compressDist(dist);
  expect(first.written.sort()).toEqual([`${APP}.br`, `${APP}.gz`]);
});

afterAll(() => rmSync(work, { recursive: true, force: true }));

// ---------------------------------------------------------------- the child process

interface LogEntry {
  time: string;
  level: string;
  msg: string;
  [k: string]: unknown;
}

interface Started {
  child: ChildProcess;
  port: number;
  base: string;
  dataDir: string;
  stdout: string[];
  stderr: string[];
  /** JSON log entries (SHOPDECK_LOG=json). */
  entries: LogEntry[];
  exited: Promise<{ code: number | null; signal: NodeJS.Signals | null; at: number }>;
  stop(): Promise<void>;
}

const running = new Set<Started>();
afterEach(async () => {
  for (const s of running) await s.stop();
  running.clear();
});

function cleanEnv(): NodeJS.ProcessEnv {
  const env: NodeJS.ProcessEnv = {};
  for (const [k, v] of Object.entries(process.env))
    if (!k.startsWith('SHOPDECK_') && k !== 'PORT') env[k] = v;
  return env;
}

function startServer(
  opts: { env?: Record<string, string>; args?: string[]; dataDir?: string; json?: boolean } = {},
): Promise<Started> {
  const dataDir = opts.dataDir ?? mkdtempSync(path.join(work, 'data-'));
  const cwd = mkdtempSync(path.join(work, 'cwd-')); // no machines.json here: the demo fleet
  const child = spawn(
    process.execPath,
    [
      '--import',
      tsxLoader,
      mainTs,
      '--dist',
      dist,
      '--host',
      '127.0.0.1',
      '--port',
      '0',
      ...(opts.args ?? []),
    ],
    {
      cwd,
      env: {
        ...cleanEnv(),
        TSX_TSCONFIG_PATH: path.join(root, 'tsconfig.json'),
        SHOPDECK_DATA: dataDir,
        ...(opts.json === false ? {} : { SHOPDECK_LOG: 'json' }),
        ...opts.env,
      },
      stdio: ['ignore', 'pipe', 'pipe'],
    },
  );
  const stdout: string[] = [];
  const stderr: string[] = [];
  const entries: LogEntry[] = [];
  const exited = new Promise<{ code: number | null; signal: NodeJS.Signals | null; at: number }>((r) =>
    child.once('exit', (code, signal) => r({ code, signal, at: Date.now() })),
  );
  const lines = (stream: NodeJS.ReadableStream, into: string[]): void => {
    let rest = '';
    stream.setEncoding('utf8');
    stream.on('data', (chunk: string) => {
      const parts = (rest + chunk).split('\n');
      rest = parts.pop() ?? '';
      for (const line of parts) {
        into.push(line);
        if (line.startsWith('{')) {
          try {
            entries.push(JSON.parse(line) as LogEntry);
          } catch {
            /* not a log entry */
          }
        }
      }
    });
  };
  if (child.stdout) lines(child.stdout, stdout);
  if (child.stderr) lines(child.stderr, stderr);
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => {
      child.kill('SIGKILL');
      reject(new Error(`the server did not start:\n${[...stdout, ...stderr].join('\n')}`));
    }, 20_000);
    void exited.then(({ code }) => {
      clearTimeout(timer);
      reject(new Error(`the server exited (${code}):\n${[...stdout, ...stderr].join('\n')}`));
    });
    const poll = setInterval(() => {
      const text = stdout.join('\n');
      const json = entries.find((e) => e.msg === 'listening');
      const port = json
        ? Number(json.port)
        : Number(/https?:\/\/127\.0\.0\.1:(\d+)\//.exec(text)?.[1] ?? NaN);
      if (!Number.isFinite(port)) return;
      clearInterval(poll);
      clearTimeout(timer);
      const scheme = json ? (json.https ? 'https' : 'http') : /https:\/\//.test(text) ? 'https' : 'http';
      const started: Started = {
        child,
        port,
        base: `${scheme}://127.0.0.1:${port}`,
        dataDir,
        stdout,
        stderr,
        entries,
        exited,
        stop: async () => {
          if (child.exitCode === null && child.signalCode === null) {
            child.kill('SIGKILL');
            await exited;
          }
        },
      };
      running.add(started);
      resolve(started);
    }, 25);
  });
}

// ---------------------------------------------------------------- requests

interface Answer {
  status: number;
  headers: IncomingHttpHeaders;
  body: Buffer;
  peerFingerprint?: string;
}

function request(
  url: string,
  opts: { method?: string; headers?: Record<string, string>; body?: string; ca?: string } = {},
): Promise<Answer> {
  const u = new URL(url);
  const lib = u.protocol === 'https:' ? https : http;
  return new Promise((resolve, reject) => {
    const req = lib.request(
      u,
      {
        method: opts.method ?? 'GET',
        headers: opts.headers,
        agent: false,
        ...(opts.ca ? { ca: opts.ca } : {}),
      },
      (res) => {
        const chunks: Buffer[] = [];
        const peer = u.protocol === 'https:' ? (res.socket as TLSSocket).getPeerCertificate() : null;
        res.on('data', (c: Buffer) => chunks.push(c));
        res.on('end', () =>
          resolve({
            status: res.statusCode ?? 0,
            headers: res.headers,
            body: Buffer.concat(chunks),
            ...(peer?.fingerprint256 ? { peerFingerprint: peer.fingerprint256 } : {}),
          }),
        );
      },
    );
    req.on('error', reject);
    req.end(opts.body);
  });
}

// ---------------------------------------------------------------- tests

describe('precompression (server/compress.ts)', () => {
  it('writes .br and .gz once, never for source maps, and again only when the file changes', async () => {
    const again = await compressDist(dist);
    expect(again.written).toEqual([]);
    expect(again.upToDate).toBe(2);
    expect(existsSync(path.join(dist, `${APP}.map.br`))).toBe(false);
    expect(brotliDecompressSync(readFileSync(path.join(dist, `${APP}.br`))).toString()).toBe(appSource);
    expect(gunzipSync(readFileSync(path.join(dist, `${APP}.gz`))).toString()).toBe(appSource);

    const other = mkdtempSync(path.join(work, 'dist-'));
    const file = path.join(other, 'big.js');
    writeFileSync(file, appSource);
    expect((await compressDist(other)).written).toHaveLength(2);
    writeFileSync(file, appSource + '// changed\n'.repeat(10));
    expect((await compressDist(other)).written.sort()).toEqual(['big.js.br', 'big.js.gz']);
    expect(brotliDecompressSync(readFileSync(`${file}.br`)).toString()).toContain('// changed');
  });
});

describe('the server on plain HTTP (child process)', () => {
  let s: Started;
  beforeAll(async () => {
    s = await startServer();
    running.delete(s); // shared by the tests of this block: stopped in afterAll
  });
  afterAll(async () => s.stop());

  it('prints where it listens, the demo fleet and open mode', () => {
    const start = s.entries.find((e) => e.msg === 'listening');
    expect(start).toMatchObject({
      level: 'info',
      urls: [`http://127.0.0.1:${s.port}/`],
      machines: { file: null, demo: true, count: 6 },
      users: { mode: 'open' },
      https: null,
    });
    expect(typeof start?.time).toBe('string');
    for (const line of s.stdout.filter(Boolean)) expect(() => JSON.parse(line) as unknown).not.toThrow();
  });

  it('serves hashed assets as immutable and precompressed when accepted', async () => {
    const plainAnswer = await request(`${s.base}/${APP}`);
    expect(plainAnswer.status).toBe(200);
    expect(plainAnswer.headers['cache-control']).toBe(IMMUTABLE);
    expect(plainAnswer.headers['content-encoding']).toBeUndefined();
    expect(plainAnswer.body.toString()).toBe(appSource);

    const br = await request(`${s.base}/${APP}`, { headers: { 'Accept-Encoding': 'gzip, deflate, br' } });
    expect(br.status).toBe(200);
    expect(br.headers['content-encoding']).toBe('br');
    expect(br.headers['content-type']).toMatch(/javascript/);
    expect(br.headers['cache-control']).toBe(IMMUTABLE);
    expect(br.headers.vary).toMatch(/Accept-Encoding/i);
    expect(brotliDecompressSync(br.body).toString()).toBe(appSource);

    const gz = await request(`${s.base}/${APP}`, { headers: { 'Accept-Encoding': 'gzip' } });
    expect(gz.headers['content-encoding']).toBe('gzip');
    expect(gunzipSync(gz.body).toString()).toBe(appSource);

    const missing = await request(`${s.base}/assets/app-nothere.js`);
    expect(missing.status).toBe(404);
  });

  it('serves index.html with no-cache, the page headers, and as the fallback of app routes', async () => {
    for (const p of ['/', '/index.html', '/m/x', '/m/laser-1/settings']) {
      const r = await request(`${s.base}${p}`);
      expect(r.status, p).toBe(200);
      expect(r.headers['content-type'], p).toMatch(/text\/html/);
      expect(r.headers['cache-control'], p).toBe('no-cache');
      expect(r.body.toString(), p).toBe(INDEX);
      const csp = String(r.headers['content-security-policy']);
      const scriptSrc = csp.split(';').find((d) => d.trim().startsWith('script-src'));
      expect(scriptSrc?.trim(), p).toBe("script-src 'self'");
      expect(csp).toContain("frame-ancestors 'none'");
      expect(r.headers['x-content-type-options']).toBe('nosniff');
      expect(r.headers['x-frame-options']).toBe('DENY');
      expect(r.headers['referrer-policy']).toBe('no-referrer');
      expect(r.headers['strict-transport-security']).toBeUndefined();
    }
    const etag = (await request(`${s.base}/`)).headers.etag ?? '';
    expect((await request(`${s.base}/`, { headers: { 'If-None-Match': etag } })).status).toBe(304);
    expect((await request(`${s.base}/`, { method: 'POST', body: 'x' })).status).toBe(405);
  });

  it('never serves source maps', async () => {
    expect(existsSync(path.join(dist, `${APP}.map`))).toBe(true);
    for (const p of [`/${APP}.map`, `/${APP}.map?x=1`, `/${APP}.MAP`, `/${APP}.map.br`]) {
      const r = await request(`${s.base}${p}`, { headers: { 'Accept-Encoding': 'br, gzip' } });
      expect(r.status, p).toBe(404);
      expect(r.body.toString(), p).not.toContain('secret.ts');
    }
  });

  it('mounts the gateway: /api and /machines', async () => {
    const r = await request(`${s.base}/api/machines`, { headers: { 'X-Shopdeck': '1' } });
    expect(r.status).toBe(200);
    const body = JSON.parse(r.body.toString()) as { machines: Array<{ id: string }>; demo: boolean };
    expect(body.demo).toBe(true);
    expect(body.machines.map((m) => m.id)).toContain('demo-prunt');
    expect((await request(`${s.base}/machines/nope/status`)).status).toBe(404);
  });

  it('/healthz says whether the machines and users files loaded (503 when not)', async () => {
    const ok = await request(`${s.base}/healthz`);
    expect(ok.status).toBe(200);
    expect(ok.headers['cache-control']).toBe('no-store');
    const h = JSON.parse(ok.body.toString()) as Record<string, unknown>;
    expect(h).toMatchObject({
      ok: true,
      machines: { loaded: true, file: null, demo: true, count: 6 },
      users: { mode: 'open', file: path.join(s.dataDir, 'users.json') },
      https: false,
      stopping: false,
    });
    expect(typeof h.uptime).toBe('number');

    const usersFile = path.join(s.dataDir, 'users.json');
    writeFileSync(usersFile, '{ "users": [ { "name": "ana", "role": "boss" } ] }');
    try {
      const bad = await request(`${s.base}/healthz`);
      expect(bad.status).toBe(503);
      expect(JSON.parse(bad.body.toString())).toMatchObject({
        ok: false,
        users: { mode: 'secured', loaded: false, error: expect.stringContaining('users.json') as unknown },
      });
    } finally {
      rmSync(usersFile);
    }
    expect((await request(`${s.base}/healthz`)).status).toBe(200);
  });
});

describe('starting and stopping', () => {
  it('on SIGTERM closes an open WebSocket with 1001 (going away) and exits 0 within 5 s', async () => {
    const s = await startServer();
    const origin = `http://127.0.0.1:${s.port}`;
    const ws = new WebSocket(`ws://127.0.0.1:${s.port}/machines/demo-prunt/websocket/everything`, {
      headers: { Origin: origin },
    });
    const first = new Promise<string>((resolve, reject) => {
      ws.once('message', (d) => resolve(String(d)));
      ws.once('error', reject);
    });
    const closed = new Promise<{ code: number; reason: string }>((r) =>
      ws.once('close', (code, reason) => r({ code, reason: reason.toString() })),
    );
    expect(JSON.parse(await first)).toHaveProperty('Server_Start_Time');

    const t0 = Date.now();
    s.child.kill('SIGTERM');
    const close = await closed;
    expect(close.code).toBe(1001);
    expect(close.reason).toMatch(/shutting down/);
    const exit = await s.exited;
    expect(exit.code).toBe(0);
    expect(exit.at - t0).toBeLessThan(5000);
    expect(s.entries.find((e) => e.msg === 'stopped')).toMatchObject({ goingAway: 1 });
  });

  it('refuses to serve open mode on the network, as the Vite plugin does', async () => {
    await expect(startServer({ args: ['--host', '0.0.0.0'] })).rejects.toThrow(
      /exited \(1\)[\s\S]*open mode[\s\S]*SHOPDECK_OPEN=1/,
    );
  });
});

describe('HTTPS', () => {
  it('makes and keeps a self-signed certificate, prints its fingerprint, sends HSTS and Secure cookies, redirects HTTP', async () => {
    const dataDir = mkdtempSync(path.join(work, 'data-tls-'));
    writeFileSync(
      path.join(dataDir, 'users.json'),
      JSON.stringify({
        users: [{ name: 'ana', role: 'supervisor', passwordHash: bcrypt.hashSync('correct-horse-1', 4) }],
      }),
    );
    const s = await startServer({
      dataDir,
      json: false,
      env: { SHOPDECK_HTTPS: '1', SHOPDECK_HTTP_REDIRECT_PORT: '0' },
    });
    expect(s.base).toBe(`https://127.0.0.1:${s.port}`);
    const text = s.stdout.join('\n');
    const printed = /certificate SHA-256 ((?:[0-9A-F]{2}:){31}[0-9A-F]{2})/.exec(text)?.[1];
    expect(printed, text).toBeDefined();
    expect(text).toMatch(/users: +1 from .*users\.json/);
    expect(text).toMatch(/machines: 6 from the built-in demo fleet/);

    // The kept files: a CA that a tablet trusts, and the server certificate it signed.
    const caPem = readFileSync(path.join(dataDir, 'tls', 'shopdeck-ca.crt'), 'utf8');
    const ca = new X509Certificate(caPem);
    const leaf = new X509Certificate(readFileSync(path.join(dataDir, 'tls', 'server.crt'), 'utf8'));
    expect(leaf.fingerprint256).toBe(printed);
    expect(leaf.checkIssued(ca)).toBe(true);
    expect(leaf.verify(ca.publicKey)).toBe(true);
    expect(leaf.ca).toBe(false);
    expect(ca.ca).toBe(true);
    expect(leaf.subjectAltName).toContain('IP Address:127.0.0.1');
    expect(leaf.subjectAltName).toContain('DNS:localhost');
    expect(text).toContain(`CA SHA-256 ${ca.fingerprint256}`);
    expect(existsSync(path.join(dataDir, 'tls', 'ca.key'))).toBe(false);

    // A client that trusts the CA (as a tablet would) connects without any exception.
    const page = await request(`${s.base}/m/x`, { ca: caPem });
    expect(page.status).toBe(200);
    expect(page.peerFingerprint).toBe(printed);
    expect(page.headers['strict-transport-security']).toBe('max-age=31536000');
    expect(page.headers['content-security-policy']).toContain("frame-ancestors 'none'");
    expect(
      (await request(`${s.base}/${APP}`, { ca: caPem })).headers['strict-transport-security'],
    ).toBeDefined();
    // The CA over HTTPS: the file, and a page with its fingerprint and the download link.
    const caDownload = await request(`${s.base}/shopdeck-ca.crt`, { ca: caPem });
    expect(caDownload.body.toString()).toBe(caPem);
    expect(caDownload.headers['content-type']).toBe('application/x-x509-ca-cert');
    const caPage = await request(`${s.base}/shopdeck-ca`, { ca: caPem });
    expect(caPage.status).toBe(200);
    expect(caPage.headers['content-type']).toMatch(/^text\/html/);
    expect(caPage.headers['content-security-policy']).toContain("frame-ancestors 'none'");
    expect(caPage.body.toString()).toContain(ca.fingerprint256);
    expect(caPage.body.toString()).toContain('href="/shopdeck-ca.crt"');
    expect(caPage.body.toString()).not.toContain('BEGIN CERTIFICATE');
    // The start output says where that page is, over HTTPS.
    expect(text).toMatch(new RegExp(`https://127\\.0\\.0\\.1:${s.port}/shopdeck-ca `));

    const login = await request(`${s.base}/api/login`, {
      ca: caPem,
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1' },
      body: JSON.stringify({ name: 'ana', password: 'correct-horse-1' }),
    });
    expect(login.status).toBe(200);
    const cookie = String(login.headers['set-cookie']?.[0] ?? '');
    expect(cookie).toMatch(/^shopdeck_session=/);
    expect(cookie).toMatch(/; Secure/);
    expect(cookie).toMatch(/HttpOnly/);

    // Finding 5 on the real server: a (simulated) machine's answer and /api answers are never
    // kept, and logout tells the browser to forget its cache and storage.
    const session = cookie.split(';')[0] ?? '';
    for (const p of ['/machines/demo-prunt/update_check', '/api/machines', '/api/session']) {
      const r = await request(`${s.base}${p}`, {
        ca: caPem,
        headers: { Cookie: session, 'X-Shopdeck': '1' },
      });
      expect(r.headers['cache-control'], `${p} (${r.status})`).toBe('no-store');
      expect(r.headers.etag, p).toBeUndefined();
    }
    const logout = await request(`${s.base}/api/logout`, {
      ca: caPem,
      method: 'POST',
      headers: { Cookie: session, 'X-Shopdeck': '1' },
    });
    expect(logout.status).toBe(200);
    expect(logout.headers['clear-site-data']).toBe('"cache", "storage"');
    expect(logout.headers['cache-control']).toBe('no-store');

    const redirectPort = Number(/plain HTTP on port (\d+) redirects/.exec(text)?.[1]);
    const redirected = await request(`http://127.0.0.1:${redirectPort}/m/x?tab=2`);
    expect(redirected.status).toBe(301);
    expect(redirected.headers.location).toBe(`https://127.0.0.1:${s.port}/m/x?tab=2`);
    const posted = await request(`http://127.0.0.1:${redirectPort}/api/login`, {
      method: 'POST',
      body: '{}',
    });
    expect(posted.status).toBe(400);
    const evil = await request(`http://127.0.0.1:${redirectPort}/`, { headers: { Host: 'evil.example' } });
    expect(evil.headers.location).toBe(`https://127.0.0.1:${s.port}/`);

    // Finding 16: the CA a tablet is told to trust is never served over plain HTTP (anyone on
    // the Wi-Fi could swap it for their own): the redirect port only redirects, for every
    // spelling of its path and method.
    for (const p of [
      '/shopdeck-ca.crt',
      '/shopdeck-ca.crt?x=1',
      '/shopdeck-ca',
      '/SHOPDECK-CA.CRT',
      '//shopdeck-ca.crt',
    ]) {
      for (const method of ['GET', 'HEAD']) {
        const plainCa = await request(`http://127.0.0.1:${redirectPort}${p}`, { method });
        expect(plainCa.status, `${method} ${p}`).toBe(301);
        expect(plainCa.headers.location, `${method} ${p}`).toMatch(
          new RegExp(`^https://127\\.0\\.0\\.1:${s.port}/`),
        );
        expect(plainCa.headers['content-type'], `${method} ${p}`).toBeUndefined();
        expect(plainCa.body.toString(), `${method} ${p}`).toBe('');
      }
    }

    s.child.kill('SIGTERM');
    expect((await s.exited).code).toBe(0);
    const db = new Database(path.join(dataDir, 'history.sqlite'), { readonly: true });
    const audit = JSON.stringify(db.prepare('SELECT entry FROM audit').all());
    db.close();
    expect(audit).toContain('\\"type\\":\\"login\\"');

    // Started again: the same certificate (tablets keep trusting it).
    const again = await startServer({ dataDir, env: { SHOPDECK_HTTPS: '1' } });
    const start = again.entries.find((e) => e.msg === 'listening');
    expect(start?.https).toMatchObject({ source: 'self-signed', fingerprint: printed });
    expect((await request(`${again.base}/`, { ca: caPem })).peerFingerprint).toBe(printed);
    // Two server starts and some forty requests on a machine shared with other work: generous.
  }, 60_000);

  it('serves the certificate and key of SHOPDECK_TLS_CERT and SHOPDECK_TLS_KEY', async () => {
    const made = mkdtempSync(path.join(work, 'data-made-'));
    const first = await startServer({ dataDir: made, env: { SHOPDECK_HTTPS: '1' } });
    await first.stop();
    const certFile = path.join(made, 'tls', 'server.crt');
    const fingerprint = new X509Certificate(readFileSync(certFile, 'utf8')).fingerprint256;
    const s = await startServer({
      env: { SHOPDECK_TLS_CERT: certFile, SHOPDECK_TLS_KEY: path.join(made, 'tls', 'server.key') },
    });
    expect(s.entries.find((e) => e.msg === 'listening')?.https).toMatchObject({
      source: 'files',
      fingerprint,
    });
    const r = await request(`${s.base}/healthz`, {
      ca: readFileSync(path.join(made, 'tls', 'shopdeck-ca.crt'), 'utf8'),
    });
    expect(r.status).toBe(200);
    expect(r.peerFingerprint).toBe(fingerprint);
    expect(JSON.parse(r.body.toString())).toMatchObject({ ok: true, https: true });

    await expect(startServer({ env: { SHOPDECK_TLS_CERT: certFile } })).rejects.toThrow(
      /set both SHOPDECK_TLS_CERT and SHOPDECK_TLS_KEY/,
    );
    // Three server processes one after another (about 4 s each here, more on a loaded machine).
  }, 60_000);
});
