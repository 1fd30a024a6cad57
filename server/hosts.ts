import type http from 'node:http';
import type { IncomingMessage } from 'node:http';
import { isIP, type AddressInfo } from 'node:net';
import os from 'node:os';
import { cleanNames } from './tls-cert';

/** Where the server listens (host, ports, URLs) and the host names it answers to (DNS rebinding). */

export const DEFAULT_PORT = 4173;
export const DEFAULT_HOST = 'localhost';

export function envPort(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (v === undefined || v === '') return undefined;
  const n = Number(v);
  if (!Number.isInteger(n) || n < 0 || n > 65535)
    throw new Error(`shopdeck: ${key}=${v} is not a port number`);
  return n;
}

export function listFromEnv(v: string | undefined): string[] {
  return (v ?? '')
    .split(',')
    .map((s) => s.trim())
    .filter(Boolean);
}

const WILDCARD = new Set(['', '0.0.0.0', '::', '[::]']);

export function isWildcard(host: string | true): boolean {
  return host === true || WILDCARD.has(host);
}

export function bracket(host: string): string {
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

export function hostnameOf(req: IncomingMessage): string | null {
  try {
    const h = new URL(`http://${req.headers.host ?? ''}`).hostname;
    return h || null;
  } catch {
    return null;
  }
}

/** The gateway's rule (context.ts `hostAllowed`): IP addresses and localhost always, else the list. */
export function hostAllowedBy(allowed: true | readonly string[], req: IncomingMessage): boolean {
  if (allowed === true) return true;
  const hostname = hostnameOf(req)?.replace(/^\[|\]$/g, '');
  if (!hostname) return false;
  if (hostname === 'localhost' || hostname.endsWith('.localhost') || isIP(hostname)) return true;
  return allowed.some((a) =>
    a.startsWith('.') ? hostname === a.slice(1) || hostname.endsWith(a) : hostname === a.toLowerCase(),
  );
}

/**
 * The host names the console answers to besides IP addresses and localhost: the listen host, this
 * computer's name and `<name>.local`, the certificate's names, and `SHOPDECK_ALLOWED_HOSTS`
 * (comma-separated; `*` or `true` for any).
 */
export function defaultAllowedHosts(o: {
  host: string | true;
  env: NodeJS.ProcessEnv;
  /** `SHOPDECK_TLS_NAMES`. */
  extraNames: readonly string[];
  /** The certificate's names (none without HTTPS). */
  tlsNames: readonly string[];
}): true | string[] {
  const { host } = o;
  const listed = listFromEnv(o.env.SHOPDECK_ALLOWED_HOSTS);
  if (listed.includes('*') || listed.includes('true')) return true;
  const own = os.hostname().toLowerCase();
  return [
    ...(typeof host === 'string' && !isWildcard(host) && !isIP(host) ? [host.toLowerCase()] : []),
    own,
    ...(own.includes('.') ? [] : [`${own}.local`]),
    ...cleanNames(o.extraNames).filter((n) => !isIP(n)),
    ...o.tlsNames.filter((n) => !isIP(n) && !n.startsWith('*')),
    ...listed.map((s) => s.toLowerCase()),
  ].filter((v, i, a) => a.indexOf(v) === i);
}

export function isLoopback(address: string | undefined): boolean {
  return address === '::1' || /^(::ffff:)?127\./.test(address ?? '');
}

/** Listens on `host:p`; the port bound. A port in use or not allowed rejects with what to do. */
export function listenOn(s: http.Server, host: string | true, p: number, what: string): Promise<number> {
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
