import { existsSync } from 'node:fs';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import path from 'node:path';
import type { Duplex } from 'node:stream';
import sirv from 'sirv';
import { families } from '../src/controllers/families';
import { createGateway, type Gateway } from '../gateway/gateway';
import { loadMachines, type MachinesConfig } from '../gateway/machines';
import { pageHeadersMiddleware } from '../gateway/page-headers';
import { openModeExposure } from '../gateway/plugin';
import { dataDirPath, readUsers, usersFilePath } from '../gateway/users';
import { logBanner, type StartInfo } from './banner';
import { guardBody, type BodyDeadline } from './body-deadline';
import { CA_PAGE_PATH, CA_PATH, serveCa, serveCaPage } from './ca-page';
import { answerHealth, createHealth, type HealthReport } from './health';
import {
  bracket,
  DEFAULT_HOST,
  DEFAULT_PORT,
  defaultAllowedHosts,
  envPort,
  hostAllowedBy,
  hostnameOf,
  isWildcard,
  listenOn,
  listFromEnv,
  urlsFor,
} from './hosts';
import { createLogger, type Logger } from './log';
import { defaultNames, type TlsMaterial } from './tls-cert';
import { httpsFromEnv, ServerTls, type HttpsSetting } from './tls-setup';

/**
 * Shopdeck's own server (`npm start`): the built console from `dist/` and the gateway, as the Vite
 * plugin mounts it, on node:http or node:https (README.md "Running it for the shop"). Source maps
 * are never served. Beside it: hosts.ts, tls-setup.ts, ca-page.ts (`/shopdeck-ca`), health.ts
 * (`/healthz`), banner.ts. `close()` stops within 5 s (WebSockets closed with 1001).
 */

export { CA_PAGE_PATH, CA_PATH, caPageHtml } from './ca-page';
export { DEFAULT_HOST, DEFAULT_PORT, urlsFor } from './hosts';
export type { HealthReport } from './health';
export type { HttpsSetting } from './tls-setup';
export type { StartInfo } from './banner';

export const IMMUTABLE = 'public, max-age=31536000, immutable';
export const HSTS = 'max-age=31536000';

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
  const securedAtStart = readUsers(usersFile) !== null;
  const openOnNetwork = openModeExposure(host, env, usersFile);

  // HTTPS
  const setting = opts.https ?? httpsFromEnv(env, cwd);
  const extraNames = listFromEnv(env.SHOPDECK_TLS_NAMES);
  const serverTls = new ServerTls(setting, dataDir, () =>
    defaultNames([...extraNames, ...(typeof host === 'string' && !isWildcard(host) ? [host] : [])]),
  );
  // Whether this server is HTTPS: a reload replaces the certificate, never the scheme.
  const tlsAtStart = serverTls.current;

  const allowedHosts: true | readonly string[] =
    opts.allowedHosts || defaultAllowedHosts({ host, env, extraNames, tlsNames: tlsAtStart?.names ?? [] });

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

  let stopping = false;
  const health: () => HealthReport = createHealth({
    usersFile,
    machines,
    securedAtStart,
    https: () => serverTls.current !== null,
    stopping: () => stopping,
  });

  function afterGateway(req: IncomingMessage, res: ServerResponse): void {
    const raw = req.url ?? '/';
    const pathname = raw.split(/[?#]/, 1)[0] ?? '/';
    const method = (req.method ?? 'GET').toUpperCase();
    if (!hostAllowedBy(allowedHosts, req)) return plain(res, 403, 'this host name is not allowed');
    if (pathname === '/healthz') {
      if (method !== 'GET' && method !== 'HEAD')
        return plain(res, 405, 'method not allowed', { Allow: 'GET, HEAD' });
      return answerHealth(req, res, method, health());
    }
    if (method !== 'GET' && method !== 'HEAD')
      return plain(res, 405, 'method not allowed', { Allow: 'GET, HEAD' });
    // pageHeadersMiddleware refuses "*.map"; its precompressed copies too.
    if (/\.map(?:\.br|\.gz)?$/i.test(pathname)) return notFound(res);
    // Only this server answers these: it is HTTPS whenever there is a CA (the redirect port
    // below serves nothing but redirects).
    if (pathname === CA_PATH) return serveCa(res, method, serverTls.current?.ca, notFound);
    if (pathname === CA_PAGE_PATH) return serveCaPage(res, method, serverTls.current?.ca, notFound);
    if (pathname.startsWith('/assets/')) return assets(req, res, () => notFound(res));
    pages(req, res, () => notFound(res));
  }

  function handle(req: IncomingMessage, res: ServerResponse): void {
    guardBody(req, res, bodyDeadline);
    if (tlsAtStart) res.setHeader('Strict-Transport-Security', HSTS);
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

  const server: http.Server | https.Server = tlsAtStart
    ? https.createServer({ key: tlsAtStart.key, cert: tlsAtStart.cert }, handle)
    : http.createServer(handle);
  // The gateway bounds its own work; a slow client must not hold a request open for ever: the
  // headers by Node (headersTimeout works without requestTimeout), the body by guardBody. Node's
  // requestTimeout would cut an upload that takes long to send, so it is off.
  server.headersTimeout = 30_000;
  server.requestTimeout = 0;
  if (tlsAtStart) server.on('tlsClientError', () => undefined); // a tablet refusing the certificate: not our error

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
    tlsAtStart && redirectPort !== null
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

  // Renewed certificates and an expired self-signed one: checked hourly (tls-setup.ts).
  let tlsTimer: NodeJS.Timeout | null = null;

  async function listen(): Promise<StartInfo> {
    listenPort = await listenOn(server, host, port, tlsAtStart ? 'HTTPS' : 'HTTP');
    let boundRedirect: number | null = null;
    if (redirect && redirectPort !== null) {
      try {
        boundRedirect = await listenOn(redirect, host, redirectPort, 'the HTTP redirect');
      } catch (e) {
        server.close();
        throw e;
      }
    }
    if (!tlsAtStart && redirectPort !== null)
      log.warn('SHOPDECK_HTTP_REDIRECT_PORT is ignored: the console does not serve HTTPS', { redirectPort });
    if (tlsAtStart && server instanceof https.Server) {
      const s = server;
      tlsTimer = setInterval(() => serverTls.refresh(s, log), 3_600_000);
      tlsTimer.unref();
    }
    const info: StartInfo = {
      urls: urlsFor(host, listenPort, tlsAtStart ? 'https' : 'http'),
      port: listenPort,
      redirectPort: boundRedirect,
    };
    logBanner(log, info, {
      distDir,
      dataDir,
      machines,
      users: health().users,
      openOnNetwork,
      tls: serverTls.current,
      tlsNotes: serverTls.notes,
    });
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
      return serverTls.current;
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
