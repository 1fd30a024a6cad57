import { existsSync } from 'node:fs';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import { isIP, type AddressInfo } from 'node:net';
import os from 'node:os';
import path from 'node:path';
import type { Duplex } from 'node:stream';
import sirv from 'sirv';
import { families } from '../src/controllers/families';
import { createGateway, type Gateway } from '../gateway/gateway';
import { loadMachines, type MachinesConfig } from '../gateway/machines';
import { pageHeadersMiddleware } from '../gateway/page-headers';
import { openModeExposure } from '../gateway/plugin';
import { dataDirPath, readUsers, usersFilePath } from '../gateway/users';
import { guardBody, type BodyDeadline } from './body-deadline';
import { createLogger, type Logger } from './log';
import {
  cleanNames,
  defaultNames,
  ensureSelfSigned,
  filesStamp,
  loadTlsFiles,
  TlsSetupError,
  type TlsMaterial,
} from './tls-cert';

/**
 * Shopdeck's own server (`npm start`): the built console from `dist/` and the gateway, on
 * node:http or node:https, without Vite.
 *
 * - `/api/*`, `/machines/*` and their WebSocket upgrades: the gateway, exactly as the Vite plugin
 *   mounts it (gateway/plugin.ts), behind the same page security headers (gateway/page-headers.ts).
 * - `/assets/*` (hashed file names): `Cache-Control: public, max-age=31536000, immutable`.
 * - Everything else from `dist/` and the single-page fallback (`/m/laser-1` → index.html):
 *   `no-cache` with an ETag — the service worker (`/sw.js`) and `/manifest.webmanifest` too, so
 *   an installed tablet sees a new version (server/pwa.test.ts). Precompressed `.br`/`.gz`
 *   copies (server/compress.ts) are sent to browsers that accept them. Source maps are never
 *   served.
 * - `/healthz`: whether the machines and users files loaded (503 when not, or while stopping).
 * - HTTPS (`SHOPDECK_TLS_CERT`/`_KEY`, or `SHOPDECK_HTTPS=1` for a kept self-signed certificate)
 *   with HSTS; `SHOPDECK_HTTP_REDIRECT_PORT` answers plain HTTP with a redirect only (the CA
 *   download too). The made certificate's CA is offered over HTTPS only: `/shopdeck-ca` (a page
 *   with its SHA-256 fingerprint, also printed at start) and `/shopdeck-ca.crt` (the file).
 * - `close()`: stops accepting, closes WebSockets with 1001 (going away), closes the gateway
 *   (which writes pending audit summaries), syncs the audit log to disk; within 5 s.
 */

export const IMMUTABLE = 'public, max-age=31536000, immutable';
export const HSTS = 'max-age=31536000';
export const DEFAULT_PORT = 4173;
export const DEFAULT_HOST = 'localhost';
/** Where a tablet downloads the self-signed certificate's CA to trust it (over HTTPS only). */
export const CA_PATH = '/shopdeck-ca.crt';
/** The page that offers that download, with the CA's SHA-256 fingerprint to compare (HTTPS only). */
export const CA_PAGE_PATH = '/shopdeck-ca';

const escapeHtml = (t: string): string => t.replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);

/**
 * The CA download page: the fingerprint the tablet must show for the downloaded certificate (the
 * same one the server printed at start), the link, and where to switch it on. No script: it is
 * served under the console's page CSP like every page.
 */
export function caPageHtml(caFingerprint: string): string {
  const fp = escapeHtml(caFingerprint);
  return `<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>Shopdeck: trust this console on a tablet</title>
<style>body{font:16px/1.5 system-ui,sans-serif;max-width:40rem;margin:2rem auto;padding:0 1rem}code{font-size:1.05rem;word-break:break-all;background:#eef1f5;padding:.2rem .3rem}a.button{display:inline-block;padding:.6rem 1rem;border:1px solid #246;border-radius:.3rem;text-decoration:none}</style>
</head><body>
<h1>Trust this console on a tablet</h1>
<p>The console's HTTPS certificate is signed by its own small certificate authority. Install that
authority on the tablet once; after that, the tablet opens the console without a warning.</p>
<p><strong>SHA-256 fingerprint of the authority:</strong><br><code id="ca-fingerprint">${fp}</code></p>
<p>Before you trust it, compare this fingerprint with the one the server printed when it started
(<em>CA SHA-256 …</em>) and with the one the tablet shows for the downloaded certificate. If they
differ, do not install it: someone is between the tablet and the console.</p>
<p><a class="button" href="${CA_PATH}" download="shopdeck-ca.crt">Download the certificate authority</a></p>
<h2>Then</h2>
<ul>
<li><strong>Android</strong>: Settings → Security → Encryption &amp; credentials → Install a certificate → CA certificate.</li>
<li><strong>iPad</strong>: Settings → General → VPN &amp; Device Management → install the downloaded profile, then
Settings → General → About → Certificate Trust Settings → switch it on.</li>
</ul>
<p><a href="/">Back to the console</a></p>
</body></html>
`;
}

export type HttpsSetting = 'off' | 'self-signed' | { certFile: string; keyFile: string };

export interface ShopdeckServerOptions {
  /** The built console (`vite build` output) with index.html. */
  distDir: string;
  /** Host to listen on; `true` for every interface (as `vite preview --host`). Default `SHOPDECK_HOST`, else localhost. */
  host?: string | true;
  /** Default `SHOPDECK_PORT`, else `PORT`, else 4173; 0 picks a free port. */
  port?: number;
  env?: NodeJS.ProcessEnv;
  cwd?: string;
  dataDir?: string;
  machinesFile?: string;
  usersFile?: string;
  /** Default from `SHOPDECK_TLS_CERT`/`SHOPDECK_TLS_KEY`, else `SHOPDECK_HTTPS=1`, else off. */
  https?: HttpsSetting;
  /** Plain-HTTP port that only redirects to HTTPS (`SHOPDECK_HTTP_REDIRECT_PORT`); null for none. */
  httpRedirectPort?: number | null;
  /**
   * Host names the console answers to besides IP addresses and localhost (DNS rebinding
   * protection). Default: the listen host, this computer's name and `<name>.local`, the
   * certificate's names, and `SHOPDECK_ALLOWED_HOSTS` (comma-separated; `*` for any).
   */
  allowedHosts?: true | readonly string[];
  logger?: Logger;
  /** How long `close()` may take before it cuts the last connections (default 4500 ms). */
  closeTimeoutMs?: number;
  /**
   * A request body the gateway reads itself must arrive within this (ms, default 120 s); a body
   * it streams on to a controller (an upload) has no such deadline (server/body-deadline.ts).
   */
  bodyTimeoutMs?: number;
  /** A streamed upload is cut when no byte of it came for this long (ms, default 60 s). */
  uploadStallMs?: number;
}

export interface StartInfo {
  urls: string[];
  port: number;
  redirectPort: number | null;
}

export interface HealthReport {
  ok: boolean;
  machines: { loaded: boolean; file: string | null; demo: boolean; count: number };
  users:
    | { mode: 'open'; file: string }
    | { mode: 'secured'; loaded: true; file: string; count: number }
    | { mode: 'secured'; loaded: false; file: string; error: string };
  https: boolean;
  stopping: boolean;
  /** Seconds since the server started. */
  uptime: number;
}

export interface ShopdeckServer {
  readonly gateway: Gateway;
  readonly machines: MachinesConfig;
  readonly dataDir: string;
  readonly usersFile: string;
  readonly tls: TlsMaterial | null;
  readonly server: http.Server | https.Server;
  health(): HealthReport;
  listen(): Promise<StartInfo>;
  /** Graceful stop; the same promise on every call. */
  close(): Promise<void>;
}

// ---------------------------------------------------------------- configuration from the environment

function envPort(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (v === undefined || v === '') return undefined;
  const n = Number(v);
  if (!Number.isInteger(n) || n < 0 || n > 65535)
    throw new Error(`shopdeck: ${key}=${v} is not a port number`);
  return n;
}

function httpsFromEnv(env: NodeJS.ProcessEnv, cwd: string): HttpsSetting {
  const cert = env.SHOPDECK_TLS_CERT;
  const key = env.SHOPDECK_TLS_KEY;
  if (cert || key) {
    if (!cert || !key)
      throw new TlsSetupError('set both SHOPDECK_TLS_CERT and SHOPDECK_TLS_KEY (PEM files), or neither');
    return { certFile: path.resolve(cwd, cert), keyFile: path.resolve(cwd, key) };
  }
  const flag = (env.SHOPDECK_HTTPS ?? '').toLowerCase();
  return flag === '1' || flag === 'true' || flag === 'yes' ? 'self-signed' : 'off';
}

function listFromEnv(v: string | undefined): string[] {
  return (v ?? '')
    .split(',')
    .map((s) => s.trim())
    .filter(Boolean);
}

const WILDCARD = new Set(['', '0.0.0.0', '::', '[::]']);

function isWildcard(host: string | true): boolean {
  return host === true || WILDCARD.has(host);
}

function bracket(host: string): string {
  return isIP(host) === 6 ? `[${host}]` : host;
}

/** The URLs a person can open: every interface's IPv4 address when listening on all of them. */
export function urlsFor(host: string | true, port: number, scheme: 'http' | 'https'): string[] {
  const url = (h: string): string =>
    `${scheme}://${bracket(h)}${port === (scheme === 'https' ? 443 : 80) ? '' : `:${port}`}/`;
  if (!isWildcard(host)) return [url(host as string)];
  const addresses = Object.values(os.networkInterfaces())
    .flat()
    .filter((a): a is os.NetworkInterfaceInfo => !!a && !a.internal && a.family === 'IPv4')
    .map((a) => a.address);
  return [url('localhost'), ...addresses.map(url)];
}

function hostnameOf(req: IncomingMessage): string | null {
  try {
    const h = new URL(`http://${req.headers.host ?? ''}`).hostname;
    return h || null;
  } catch {
    return null;
  }
}

/** The gateway's rule (context.ts `hostAllowed`): IP addresses and localhost always, else the list. */
function hostAllowedBy(allowed: true | readonly string[], req: IncomingMessage): boolean {
  if (allowed === true) return true;
  const hostname = hostnameOf(req)?.replace(/^\[|\]$/g, '');
  if (!hostname) return false;
  if (hostname === 'localhost' || hostname.endsWith('.localhost') || isIP(hostname)) return true;
  return allowed.some((a) =>
    a.startsWith('.') ? hostname === a.slice(1) || hostname.endsWith(a) : hostname === a.toLowerCase(),
  );
}

function isLoopback(address: string | undefined): boolean {
  return address === '::1' || /^(::ffff:)?127\./.test(address ?? '');
}

/** /healthz for the network: healthy or not, and why in one word each, without paths or counts. */
function publicHealth(h: HealthReport): Record<string, unknown> {
  return {
    ok: h.ok,
    machines: { loaded: h.machines.loaded },
    users: { mode: h.users.mode, loaded: h.users.mode === 'open' || h.users.loaded },
    https: h.https,
    stopping: h.stopping,
  };
}

function plain(
  res: ServerResponse,
  status: number,
  text: string,
  headers: Record<string, string> = {},
): void {
  res.writeHead(status, {
    'Content-Type': 'text/plain; charset=utf-8',
    'Content-Length': Buffer.byteLength(text),
    'Cache-Control': 'no-store',
    ...headers,
  });
  res.end(text);
}

const delay = (ms: number): Promise<void> =>
  new Promise((r) => {
    setTimeout(r, Math.max(0, ms)).unref();
  });

// ---------------------------------------------------------------- the server

export function createShopdeckServer(opts: ShopdeckServerOptions): ShopdeckServer {
  const env = opts.env ?? process.env;
  const cwd = opts.cwd ?? process.cwd();
  const log = opts.logger ?? createLogger();
  const distDir = path.resolve(cwd, opts.distDir);
  if (!existsSync(path.join(distDir, 'index.html')))
    throw new Error(`shopdeck: no built console in ${distDir} (index.html is missing): run npm run build`);
  const host: string | true = opts.host ?? (env.SHOPDECK_HOST || DEFAULT_HOST);
  const port = opts.port ?? envPort(env, 'SHOPDECK_PORT') ?? envPort(env, 'PORT') ?? DEFAULT_PORT;
  const redirectPort =
    opts.httpRedirectPort === undefined
      ? (envPort(env, 'SHOPDECK_HTTP_REDIRECT_PORT') ?? null)
      : opts.httpRedirectPort;
  const closeTimeoutMs = opts.closeTimeoutMs ?? 4500;
  const bodyDeadline: BodyDeadline = {
    totalMs: opts.bodyTimeoutMs ?? 120_000,
    stallMs: opts.uploadStallMs ?? 60_000,
  };

  // Validated before anything listens: a bad file stops the server naming the file and the field.
  const machines = loadMachines({ machinesFile: opts.machinesFile, env, cwd });
  const dataDir = dataDirPath({ dataDir: opts.dataDir, env, cwd });
  const usersFile = usersFilePath({ usersFile: opts.usersFile, dataDir, env, cwd });
  let securedOnce = readUsers(usersFile) !== null;
  const openOnNetwork = openModeExposure(host, env, usersFile);

  // HTTPS
  const setting = opts.https ?? httpsFromEnv(env, cwd);
  const extraNames = listFromEnv(env.SHOPDECK_TLS_NAMES);
  const wantedNames = (): string[] =>
    defaultNames([...extraNames, ...(typeof host === 'string' && !isWildcard(host) ? [host] : [])]);
  let tls: TlsMaterial | null = null;
  const tlsNotes: string[] = [];
  const loadTls = (): TlsMaterial | null => {
    if (setting === 'off') return null;
    if (setting === 'self-signed') {
      const r = ensureSelfSigned(dataDir, wantedNames());
      if (r.made === 'the kept certificate expired')
        tlsNotes.push(
          'the kept certificate had expired: a new one was made, tablets must trust its CA again',
        );
      if (r.missing.length)
        tlsNotes.push(
          `the certificate does not name ${r.missing.join(', ')}: browsers warn there. To add them, set SHOPDECK_TLS_NAMES ` +
            `if needed and delete ${path.dirname(r.material.certFile)} (a new certificate is made; tablets must trust it again)`,
        );
      return r.material;
    }
    return loadTlsFiles(setting.certFile, setting.keyFile);
  };
  tls = loadTls();
  let tlsStamp = tls ? filesStamp(tls.certFile, tls.keyFile) : '';

  const allowedHosts: true | readonly string[] = (() => {
    if (opts.allowedHosts) return opts.allowedHosts;
    const listed = listFromEnv(env.SHOPDECK_ALLOWED_HOSTS);
    if (listed.includes('*') || listed.includes('true')) return true;
    const own = os.hostname().toLowerCase();
    return [
      ...(typeof host === 'string' && !isWildcard(host) && !isIP(host) ? [host.toLowerCase()] : []),
      own,
      ...(own.includes('.') ? [] : [`${own}.local`]),
      ...cleanNames(extraNames).filter((n) => !isIP(n)),
      ...(tls?.names.filter((n) => !isIP(n) && !n.startsWith('*')) ?? []),
      ...listed.map((s) => s.toLowerCase()),
    ].filter((v, i, a) => a.indexOf(v) === i);
  })();

  const gw = createGateway({
    env,
    cwd,
    machines,
    families,
    dataDir,
    usersFile,
    allowedHosts,
    openOnNetwork,
    log,
  });

  // ---------------------------------------------------------------- static files

  const pageHeaders = pageHeadersMiddleware(false);
  const assets = sirv(distDir, {
    etag: false,
    brotli: true,
    gzip: true,
    dotfiles: false,
    setHeaders: (res) => res.setHeader('Cache-Control', IMMUTABLE),
  });
  const pages = sirv(distDir, {
    etag: true,
    brotli: true,
    gzip: true,
    dotfiles: false,
    single: true,
    setHeaders: (res) => res.setHeader('Cache-Control', 'no-cache'),
  });
  const notFound = (res: ServerResponse): void => plain(res, 404, 'not found');

  const startedAt = Date.now();
  let stopping = false;

  function health(): HealthReport {
    let users: HealthReport['users'];
    try {
      const list = readUsers(usersFile);
      if (list) {
        securedOnce = true;
        users = { mode: 'secured', loaded: true, file: usersFile, count: list.length };
      } else if (securedOnce) {
        // The gateway stays secured (nobody can log in) until the file is back: users.ts.
        users = {
          mode: 'secured',
          loaded: false,
          file: usersFile,
          error: 'the users file is gone: nobody can log in',
        };
      } else {
        users = { mode: 'open', file: usersFile };
      }
    } catch (e) {
      users = {
        mode: 'secured',
        loaded: false,
        file: usersFile,
        error: e instanceof Error ? e.message : String(e),
      };
    }
    const ok = !stopping && (users.mode === 'open' || users.loaded);
    return {
      ok,
      machines: {
        loaded: true,
        file: machines.file,
        demo: machines.file === null,
        count: machines.machines.length,
      },
      users,
      https: tls !== null,
      stopping,
      uptime: Math.round((Date.now() - startedAt) / 1000),
    };
  }

  function serveCa(res: ServerResponse, method: string): void {
    const ca = tls?.ca;
    if (!ca) return notFound(res);
    res.writeHead(200, {
      'Content-Type': 'application/x-x509-ca-cert',
      'Content-Disposition': 'attachment; filename="shopdeck-ca.crt"',
      'Content-Length': Buffer.byteLength(ca.pem),
      'Cache-Control': 'no-cache',
    });
    res.end(method === 'HEAD' ? undefined : ca.pem);
  }

  function serveCaPage(res: ServerResponse, method: string): void {
    const ca = tls?.ca;
    if (!ca) return notFound(res);
    const html = caPageHtml(ca.fingerprint);
    res.writeHead(200, {
      'Content-Type': 'text/html; charset=utf-8',
      'Content-Length': Buffer.byteLength(html),
      'Cache-Control': 'no-store',
    });
    res.end(method === 'HEAD' ? undefined : html);
  }

  function afterGateway(req: IncomingMessage, res: ServerResponse): void {
    const raw = req.url ?? '/';
    const pathname = raw.split(/[?#]/, 1)[0] ?? '/';
    const method = (req.method ?? 'GET').toUpperCase();
    if (!hostAllowedBy(allowedHosts, req)) return plain(res, 403, 'this host name is not allowed');
    if (pathname === '/healthz') {
      if (method !== 'GET' && method !== 'HEAD')
        return plain(res, 405, 'method not allowed', { Allow: 'GET, HEAD' });
      const h = health();
      // File paths, user counts and error words are for this computer (a health check, an
      // admin); anyone else on the network learns only whether the console is healthy.
      const body = JSON.stringify(isLoopback(req.socket.remoteAddress) ? h : publicHealth(h));
      res.writeHead(h.ok ? 200 : 503, {
        'Content-Type': 'application/json; charset=utf-8',
        'Content-Length': Buffer.byteLength(body),
        'Cache-Control': 'no-store',
      });
      res.end(method === 'HEAD' ? undefined : body);
      return;
    }
    if (method !== 'GET' && method !== 'HEAD')
      return plain(res, 405, 'method not allowed', { Allow: 'GET, HEAD' });
    // pageHeadersMiddleware refuses "*.map"; its precompressed copies too.
    if (/\.map(?:\.br|\.gz)?$/i.test(pathname)) return notFound(res);
    // Only this server answers these: it is HTTPS whenever there is a CA (the redirect port
    // below serves nothing but redirects).
    if (pathname === CA_PATH) return serveCa(res, method);
    if (pathname === CA_PAGE_PATH) return serveCaPage(res, method);
    if (pathname.startsWith('/assets/')) return assets(req, res, () => notFound(res));
    pages(req, res, () => notFound(res));
  }

  function handle(req: IncomingMessage, res: ServerResponse): void {
    guardBody(req, res, bodyDeadline);
    if (tls) res.setHeader('Strict-Transport-Security', HSTS);
    if (stopping) res.setHeader('Connection', 'close');
    pageHeaders(req, res, () => {
      gw.handle(req, res, (err?: unknown) => {
        if (err) {
          log.error('request failed', { path: (req.url ?? '').slice(0, 200), error: String(err) });
          if (!res.headersSent) plain(res, 500, 'internal error');
          else res.destroy();
          return;
        }
        afterGateway(req, res);
      });
    });
  }

  // ---------------------------------------------------------------- servers

  const server: http.Server | https.Server = tls
    ? https.createServer({ key: tls.key, cert: tls.cert }, handle)
    : http.createServer(handle);
  // The gateway bounds its own work; a slow client must not hold a request open for ever: the
  // headers by Node (headersTimeout works without requestTimeout), the body by guardBody. Node's
  // requestTimeout would cut an upload that takes long to send, so it is off.
  server.headersTimeout = 30_000;
  server.requestTimeout = 0;
  if (tls) server.on('tlsClientError', () => undefined); // a tablet refusing the certificate: not our error

  const upgraded = new Set<Duplex>();
  server.on('upgrade', (req: IncomingMessage, socket: Duplex, head: Buffer) => {
    socket.on('error', () => socket.destroy());
    if (stopping) {
      socket.end('HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\nContent-Length: 0\r\n\r\n');
      return;
    }
    if (!gw.upgrade(req, socket, head)) {
      socket.end('HTTP/1.1 404 Not Found\r\nConnection: close\r\nContent-Length: 0\r\n\r\n');
      return;
    }
    upgraded.add(socket);
    socket.once('close', () => upgraded.delete(socket));
  });
  server.on('clientError', (_err, socket: Duplex) => {
    if (socket.writable) socket.end('HTTP/1.1 400 Bad Request\r\nConnection: close\r\n\r\n');
    else socket.destroy();
  });

  let listenPort = port;
  const redirect =
    tls && redirectPort !== null
      ? http.createServer((req, res) => {
          const method = (req.method ?? 'GET').toUpperCase();
          // Redirects only, the CA download included: a certificate to trust, fetched in clear,
          // could be anyone's on the way (the tablet follows the redirect to HTTPS, accepts the
          // warning once, and compares the fingerprint on the page with the printed one).
          if (method !== 'GET' && method !== 'HEAD')
            return plain(res, 400, 'this port only redirects to HTTPS: nothing was done');
          const name = hostnameOf(req);
          const where =
            name && hostAllowedBy(allowedHosts, req)
              ? name
              : typeof host === 'string' && !isWildcard(host)
                ? bracket(host)
                : 'localhost';
          const target = `https://${where}${listenPort === 443 ? '' : `:${listenPort}`}${(req.url ?? '/').startsWith('/') ? req.url : '/'}`;
          res.writeHead(301, { Location: target, 'Cache-Control': 'no-store', 'Content-Length': 0 });
          res.end();
        })
      : null;

  // Renewed certificates (Let's Encrypt, a replaced file) and an expired self-signed one: checked hourly.
  let tlsTimer: NodeJS.Timeout | null = null;
  const refreshTls = (): void => {
    if (!tls || !(server instanceof https.Server)) return;
    try {
      const expired = tls.validTo.getTime() <= Date.now();
      const stamp = filesStamp(tls.certFile, tls.keyFile);
      if (stamp === tlsStamp && !expired) return;
      const next = loadTls();
      if (!next) return;
      tlsStamp = filesStamp(next.certFile, next.keyFile);
      if (next.fingerprint === tls.fingerprint) return;
      server.setSecureContext({ key: next.key, cert: next.cert });
      tls = next;
      log.warn('new HTTPS certificate', { fingerprint: next.fingerprint, ca: next.ca?.fingerprint });
    } catch (e) {
      log.error('cannot reload the HTTPS certificate: keeping the current one', {
        error: e instanceof Error ? e.message : String(e),
      });
    }
  };

  function listenOn(s: http.Server, p: number, what: string): Promise<number> {
    return new Promise((resolve, reject) => {
      const onError = (e: NodeJS.ErrnoException): void => {
        s.off('listening', onListening);
        const where = `${host === true ? 'every interface' : host}:${p}`;
        if (e.code === 'EADDRINUSE')
          reject(
            new Error(`shopdeck: ${where} is in use (${what}): stop the other server or set another port`),
          );
        else if (e.code === 'EACCES')
          reject(new Error(`shopdeck: no permission to listen on ${where} (${what}): use a port above 1023`));
        else reject(e);
      };
      const onListening = (): void => {
        s.off('error', onError);
        resolve((s.address() as AddressInfo).port);
      };
      s.once('error', onError);
      s.once('listening', onListening);
      if (host === true) s.listen(p);
      else s.listen(p, host);
    });
  }

  function banner(info: StartInfo): void {
    const users = health().users;
    const usersText =
      users.mode === 'open'
        ? `open mode (no users file at ${users.file}): anyone who reaches the console controls every machine` +
          (openOnNetwork ? ' — and it listens on the network (SHOPDECK_OPEN=1)' : '')
        : users.loaded
          ? `${users.count} from ${users.file}`
          : `${users.file}: ${users.error}`;
    const machinesText = `${machines.machines.length} from ${machines.file ?? 'the built-in demo fleet (no machines file)'}`;
    // The URL to open comes last (after the details), where a newcomer's eye lands.
    const lines = [
      `Shopdeck is serving ${distDir}`,
      `  machines: ${machinesText}`,
      `  users:    ${usersText}`,
    ];
    if (tls) {
      lines.push(
        `  HTTPS:    certificate SHA-256 ${tls.fingerprint}` +
          (tls.source === 'files'
            ? ` (${tls.certFile})`
            : ` (self-signed, kept in ${path.dirname(tls.certFile)})`),
      );
      if (tls.ca)
        lines.push(
          `            tablets: open ${info.urls[info.urls.length - 1]?.replace(/\/$/, '') ?? ''}${CA_PAGE_PATH} ` +
            `(HTTPS only), install the CA it offers and trust it if it shows CA SHA-256 ${tls.ca.fingerprint}`,
        );
      if (info.redirectPort !== null)
        lines.push(`  plain HTTP on port ${info.redirectPort} redirects to HTTPS`);
      for (const n of tlsNotes) lines.push(`  note:     ${n}`);
    }
    lines.push(`  data:     ${dataDir}`);
    lines.push(`Open the console at:`, ...info.urls.map((u) => `  ➜ ${u}`));
    log.banner('listening', lines.join('\n'), {
      urls: info.urls,
      port: info.port,
      dist: distDir,
      machines: { file: machines.file, demo: machines.file === null, count: machines.machines.length },
      users,
      openOnNetwork,
      https: tls
        ? {
            source: tls.source,
            fingerprint: tls.fingerprint,
            certFile: tls.certFile,
            validTo: tls.validTo.toISOString(),
            ...(tls.ca ? { caFingerprint: tls.ca.fingerprint, caFile: tls.ca.file } : {}),
            notes: tlsNotes,
          }
        : null,
      redirectPort: info.redirectPort,
      dataDir,
    });
  }

  async function listen(): Promise<StartInfo> {
    listenPort = await listenOn(server, port, tls ? 'HTTPS' : 'HTTP');
    let boundRedirect: number | null = null;
    if (redirect && redirectPort !== null) {
      try {
        boundRedirect = await listenOn(redirect, redirectPort, 'the HTTP redirect');
      } catch (e) {
        server.close();
        throw e;
      }
    }
    if (!tls && redirectPort !== null)
      log.warn('SHOPDECK_HTTP_REDIRECT_PORT is ignored: the console does not serve HTTPS', { redirectPort });
    if (tls) {
      tlsTimer = setInterval(refreshTls, 3_600_000);
      tlsTimer.unref();
    }
    const info: StartInfo = {
      urls: urlsFor(host, listenPort, tls ? 'https' : 'http'),
      port: listenPort,
      redirectPort: boundRedirect,
    };
    banner(info);
    return info;
  }

  let closing: Promise<void> | null = null;

  async function shutdown(): Promise<void> {
    const deadline = Date.now() + closeTimeoutMs;
    stopping = true;
    if (tlsTimer) clearInterval(tlsTimer);
    const closed = (s: http.Server | null): Promise<void> =>
      s?.listening ? new Promise((r) => s.close(() => r())) : Promise.resolve();
    // 1. No new connections; idle keep-alive connections go now.
    const allClosed = Promise.all([closed(server), closed(redirect)]);
    server.closeIdleConnections();
    redirect?.closeIdleConnections();
    // 2. WebSockets: a close frame with 1001 (going away), so pages reconnect rather than report an error.
    const sent = gw.goingAway('Shopdeck is shutting down');
    const wsDeadline = Math.min(deadline - 1000, Date.now() + 1500);
    while (upgraded.size > 0 && Date.now() < wsDeadline) await delay(25);
    // 3. The gateway: held controller sessions, simulators, upstream sockets, pending audit summaries.
    gw.close();
    try {
      // The audit database is closed (every entry was committed when it was written); alarms written.
      await Promise.race([
        Promise.all([gw.audit.close(), gw.alarms.close()]),
        delay(Math.max(0, deadline - 500 - Date.now())),
      ]);
    } catch (e) {
      log.error('cannot write the audit log to disk', { file: gw.audit.file, error: String(e) });
    }
    // 4. Requests still running get until the deadline; then their connections are cut.
    await Promise.race([allClosed, delay(deadline - Date.now())]);
    server.closeAllConnections();
    redirect?.closeAllConnections();
    for (const s of upgraded) s.destroy();
    log.info('stopped', { goingAway: sent });
  }

  return {
    gateway: gw,
    machines,
    dataDir,
    usersFile,
    get tls() {
      return tls;
    },
    server,
    health,
    listen,
    close() {
      closing ??= shutdown();
      return closing;
    },
  };
}
