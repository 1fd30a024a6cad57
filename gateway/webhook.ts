import { lookup as dnsLookup } from 'node:dns/promises';
import http from 'node:http';
import https from 'node:https';
import { BlockList, isIP, type LookupFunction } from 'node:net';
import { networkInterfaces } from 'node:os';
import type { Logger } from './log';

/**
 * Alarms sent on: each alarm event POSTed as JSON to the webhook URL of the server settings, one
 * at a time, in order, retried with backoff when the receiver is down (network error, 5xx, 408,
 * 429); a receiver that refuses (another 4xx) is told once and the event dropped with a log line.
 * The answer's body is never read beyond its status (a receiver is untrusted too), redirects are
 * not followed, and the queue is bounded (the oldest event goes first when it overflows).
 *
 * The URL is a supervisor's to set, so it must not make the gateway a way into what it guards:
 * its host is refused when it is this computer (loopback, unspecified, this computer's own
 * interface addresses), link-local (169.254/16, fe80::/10: cloud metadata, zeroconf devices),
 * multicast, or a machine of the machines file (by name or by address), unless the settings file
 * allows that host explicitly (`webhookAllowHosts`, edited on the server). A name is resolved
 * once, every address it gives is checked, and the connection goes to the checked address (a
 * name that answers differently the second time, DNS rebinding, cannot redirect it).
 */

export interface WebhookOptions {
  /** The URL now (the settings may change while events wait). */
  url(): string | null;
  log: Logger;
  /** Hosts the server's settings file allows although they would be refused (`host` or `host:port`). */
  allowedHosts?: () => readonly string[];
  /** Hosts (names or addresses) of the machines of the machines file: never a webhook receiver. */
  machineHosts?: () => readonly string[];
  /** Name resolution (tests); default the system's (`dns.lookup`, all addresses). */
  resolve?: (host: string) => Promise<Array<{ address: string; family: number }>>;
  /** Waits between tries (default 2 s, 5 s, 15 s, 60 s, 5 min, 5 min: about 12 minutes in all). */
  backoffMs?: readonly number[];
  timeoutMs?: number;
  maxQueue?: number;
}

export interface WebhookResult {
  ok: boolean;
  status?: number;
  error?: string;
}

/** Addresses a webhook never reaches unless allowed: this computer, link-local, multicast. */
const FORBIDDEN = new BlockList();
FORBIDDEN.addSubnet('0.0.0.0', 8, 'ipv4');
FORBIDDEN.addSubnet('127.0.0.0', 8, 'ipv4');
FORBIDDEN.addSubnet('169.254.0.0', 16, 'ipv4');
FORBIDDEN.addSubnet('224.0.0.0', 4, 'ipv4');
FORBIDDEN.addAddress('255.255.255.255', 'ipv4');
FORBIDDEN.addAddress('::', 'ipv6');
FORBIDDEN.addAddress('::1', 'ipv6');
FORBIDDEN.addSubnet('fe80::', 10, 'ipv6');
FORBIDDEN.addSubnet('ff00::', 8, 'ipv6');

/** An address as compared: lower case, no zone, IPv4-mapped IPv6 as the IPv4 address. */
function canonicalAddress(a: string): string {
  const bare = a
    .replace(/^\[|\]$/g, '')
    .replace(/%.*$/, '')
    .toLowerCase();
  const mapped = /^::ffff:(\d+\.\d+\.\d+\.\d+)$/.exec(bare);
  if (mapped?.[1]) return mapped[1];
  // ::ffff:7f00:1 (the mapped form in hex)
  const hex = /^::ffff:([0-9a-f]{1,4}):([0-9a-f]{1,4})$/.exec(bare);
  if (hex?.[1] && hex[2]) {
    const hi = parseInt(hex[1], 16);
    const lo = parseInt(hex[2], 16);
    return `${hi >> 8}.${hi & 255}.${lo >> 8}.${lo & 255}`;
  }
  return bare;
}

function forbiddenAddress(address: string): boolean {
  const a = canonicalAddress(address);
  const family = isIP(a);
  if (family === 0) return true; // not an address: never connect to it
  return FORBIDDEN.check(a, family === 6 ? 'ipv6' : 'ipv4');
}

/** This computer's own interface addresses (a service listening on all of them is this computer). */
function ownAddresses(): Set<string> {
  const out = new Set<string>();
  for (const list of Object.values(networkInterfaces()))
    for (const i of list ?? []) out.add(canonicalAddress(i.address));
  return out;
}

async function systemResolve(host: string): Promise<Array<{ address: string; family: number }>> {
  return dnsLookup(host, { all: true, verbatim: true });
}

/** Where a webhook may connect: the checked address (null: an allowed host, resolved as usual). */
type Target = { ok: true; address: string | null; family: number } | { ok: false; error: string };

const DEFAULT_BACKOFF = [2000, 5000, 15_000, 60_000, 300_000, 300_000];

/** Where a URL points, without its path and query (they often carry the receiver's secret). */
export function shownUrl(url: string): string {
  try {
    const u = new URL(url);
    return `${u.protocol}//${u.host}${u.pathname === '/' && !u.search ? '/' : '/…'}`;
  } catch {
    return '(not a URL)';
  }
}

/** A webhook URL a supervisor may set: http(s), no credentials in it, at most 2000 characters. */
export function webhookUrlProblem(url: string): string | null {
  if (url.length > 2000) return 'the URL is longer than 2000 characters';
  let u: URL;
  try {
    u = new URL(url);
  } catch {
    return 'not a URL';
  }
  if (u.protocol !== 'https:' && u.protocol !== 'http:') return 'the URL must start with https:// or http://';
  if (u.username || u.password) return 'put no user name or password in the URL (use a token in its path)';
  return null;
}

export class Webhook {
  private readonly queue: Array<{ body: string; what: string }> = [];
  private busy = false;
  private timer: ReturnType<typeof setTimeout> | null = null;
  private closed = false;
  /** Delivered, given up, dropped for room (tests, the settings page). */
  readonly stats = { delivered: 0, failed: 0, dropped: 0 };

  constructor(private readonly opts: WebhookOptions) {}

  /** Queues an event for the receiver (nothing when no URL is set). */
  send(what: string, payload: unknown): void {
    if (this.closed || !this.opts.url()) return;
    const max = this.opts.maxQueue ?? 200;
    if (this.queue.length >= max) {
      this.queue.shift();
      this.stats.dropped++;
      this.opts.log.warn('alarm webhook: too many events waiting; the oldest was dropped', { max });
    }
    this.queue.push({ body: JSON.stringify(payload), what });
    this.pump();
  }

  /**
   * One delivery now, not queued, not retried (the settings page's "send a test"). The reason of a
   * failure goes to the server's log only: the answer must not tell a port scanner anything.
   */
  async tryOnce(payload: unknown): Promise<WebhookResult> {
    const url = this.opts.url();
    if (!url) return { ok: false, error: 'no webhook URL is set' };
    const r = await this.post(url, JSON.stringify(payload));
    if (!r.ok)
      this.opts.log.warn(
        `alarm webhook: the test was not delivered to ${shownUrl(url)} (${r.error ?? `answered ${r.status}`})`,
      );
    return r;
  }

  /** Checks where `url` points (see the top of this file): the address to connect to, or why not. */
  async target(url: string): Promise<Target> {
    let u: URL;
    try {
      u = new URL(url);
    } catch {
      return { ok: false, error: 'not a URL' };
    }
    const host = u.hostname
      .replace(/^\[|\]$/g, '')
      .toLowerCase()
      .replace(/\.$/, '');
    const port = u.port || (u.protocol === 'https:' ? '443' : '80');
    const allowed = (this.opts.allowedHosts?.() ?? []).map((h) => h.trim().toLowerCase());
    if (
      allowed.includes(host) ||
      allowed.includes(`${host}:${port}`) ||
      allowed.includes(`[${host}]:${port}`)
    )
      return { ok: true, address: null, family: 0 };
    const machineNames = new Set<string>();
    const machineAddresses = new Set<string>();
    for (const h of this.opts.machineHosts?.() ?? []) {
      const name = h
        .replace(/^\[|\]$/g, '')
        .toLowerCase()
        .replace(/\.$/, '');
      if (isIP(canonicalAddress(name))) machineAddresses.add(canonicalAddress(name));
      else machineNames.add(name);
    }
    if (machineNames.has(host)) return { ok: false, error: `${host} is a machine of the machines file` };
    let addresses: Array<{ address: string; family: number }>;
    if (isIP(host)) addresses = [{ address: host, family: isIP(host) }];
    else {
      try {
        addresses = await (this.opts.resolve ?? systemResolve)(host);
      } catch {
        return { ok: false, error: `${host} could not be resolved` };
      }
    }
    if (addresses.length === 0) return { ok: false, error: `${host} could not be resolved` };
    // The machines' names resolved now too: a webhook name that is another name of a machine.
    for (const name of machineNames) {
      try {
        for (const a of await (this.opts.resolve ?? systemResolve)(name))
          machineAddresses.add(canonicalAddress(a.address));
      } catch {
        /* a machine that does not resolve now has no address to protect */
      }
    }
    const own = ownAddresses();
    for (const a of addresses) {
      const c = canonicalAddress(a.address);
      if (forbiddenAddress(c) || own.has(c))
        return { ok: false, error: `${host} is this computer or a link-local address (${c})` };
      if (machineAddresses.has(c)) return { ok: false, error: `${host} is a machine's address (${c})` };
    }
    const first = addresses[0];
    if (!first) return { ok: false, error: `${host} could not be resolved` };
    const address = canonicalAddress(first.address);
    return { ok: true, address, family: isIP(address) };
  }

  get waiting(): number {
    return this.queue.length;
  }

  close(): void {
    this.closed = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    this.queue.length = 0;
  }

  private pump(): void {
    if (this.busy || this.closed || this.queue.length === 0) return;
    this.busy = true;
    void this.deliver(0);
  }

  private async deliver(attempt: number): Promise<void> {
    const item = this.queue[0];
    const url = this.opts.url();
    if (!item || this.closed) {
      this.busy = false;
      return;
    }
    if (!url) {
      // The URL was removed while events waited: they are not sent anywhere.
      this.queue.length = 0;
      this.busy = false;
      return;
    }
    const r = await this.post(url, item.body);
    if (this.closed) return;
    const retry =
      !r.ok && (r.status === undefined || r.status >= 500 || r.status === 408 || r.status === 429);
    const backoff = this.opts.backoffMs ?? DEFAULT_BACKOFF;
    if (r.ok || !retry || attempt >= backoff.length) {
      this.queue.shift();
      if (r.ok) this.stats.delivered++;
      else {
        this.stats.failed++;
        this.opts.log.error(
          `alarm webhook: ${item.what} not delivered to ${shownUrl(url)} (${r.error ?? `answered ${r.status}`})${retry ? ` after ${attempt + 1} tries` : ''}`,
        );
      }
      this.busy = false;
      this.pump();
      return;
    }
    const wait = backoff[attempt] ?? 300_000;
    this.opts.log.warn(
      `alarm webhook: ${shownUrl(url)} ${r.error ?? `answered ${r.status}`}; trying again in ${Math.round(wait / 1000)} s`,
    );
    this.timer = setTimeout(() => {
      this.timer = null;
      void this.deliver(attempt + 1);
    }, wait);
    this.timer.unref?.();
  }

  private async post(url: string, body: string): Promise<WebhookResult> {
    const target = await this.target(url);
    if (!target.ok) return { ok: false, error: `refused: ${target.error}` };
    const u = new URL(url);
    // The connection goes to the address checked above, whatever the name answers now.
    const pinned: LookupFunction | undefined =
      target.address === null
        ? undefined
        : (_host, options, cb) => {
            const a = target.address ?? '';
            if (options.all) cb(null, [{ address: a, family: target.family }]);
            else cb(null, a, target.family);
          };
    const timeoutMs = this.opts.timeoutMs ?? 10_000;
    return new Promise<WebhookResult>((resolve) => {
      let done = false;
      const finish = (r: WebhookResult): void => {
        if (done) return;
        done = true;
        clearTimeout(timer);
        resolve(r);
      };
      const req = (u.protocol === 'https:' ? https : http).request(
        u,
        {
          method: 'POST',
          headers: {
            'Content-Type': 'application/json',
            'Content-Length': Buffer.byteLength(body),
            'User-Agent': 'Shopdeck alarm webhook',
          },
          ...(pinned ? { lookup: pinned } : {}),
          agent: false,
        },
        (res) => {
          // The status is all that matters; the body is not read (nor kept waiting), no redirect
          // is followed (a 3xx is a failure like any other status outside 2xx).
          const status = res.statusCode ?? 0;
          res.destroy();
          req.destroy();
          finish(status >= 200 && status <= 299 ? { ok: true, status } : { ok: false, status });
        },
      );
      const timer = setTimeout(() => {
        req.destroy();
        finish({ ok: false, error: 'no answer in time' });
      }, timeoutMs);
      timer.unref?.();
      req.on('error', (e: NodeJS.ErrnoException) => {
        finish({ ok: false, error: `could not connect${typeof e.code === 'string' ? ` (${e.code})` : ''}` });
      });
      req.end(body);
    });
  }
}
