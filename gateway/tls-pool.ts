import type http from 'node:http';
import https from 'node:https';
import type { Duplex } from 'node:stream';
import type { TLSSocket } from 'node:tls';
import type { AuditEntry } from './audit';
import type { MachineEntry } from './machines';
import { connectPinned, fingerprintOf, normalizeFingerprint, type PinRecord, type PinStore } from './tls-pin';

/**
 * Kept-alive pinned TLS connections to the controllers: one small pool per machine, for reads.
 * Node's own agent (an `https.Agent` whose `createConnection` is `connectPinned`), not undici:
 * the proxy streams through `http.request` (pipeline, redaction, `pending`, command watch), which
 * an undici Pool would replace by a second request path for the same gain; undici would also
 * re-send idempotent requests on its own, here only `sendAgain` below re-sends, and only reads.
 */

/** An idle connection is closed after this (below common controller keep-alive timeouts). */
export const IDLE_TLS_MS = 4_000;
/** Idle connections kept per machine (controllers have few sockets); busy ones are not limited. */
export const MAX_IDLE_TLS = 2;

/** The audit entry of a certificate trusted on first use (`onTrust` of `connectPinned`). */
export function trustEntry(m: Pick<MachineEntry, 'id'>, r: PinRecord): Omit<AuditEntry, 'time'> {
  return {
    type: 'tls-trust',
    result: 'ok',
    user: 'gateway',
    source: 'gateway',
    machine: m.id,
    detail: `trusted the certificate ${r.fingerprint} on first use`,
  };
}

/**
 * A read that failed because its kept-alive connection turned out closed by the controller
 * (before any answer): it may be sent once more on a new connection. Never a command.
 */
export function sendAgain(req: http.ClientRequest, e: Error & { code?: string }, method: string): boolean {
  return (
    req.reusedSocket &&
    (method === 'GET' || method === 'HEAD') &&
    (e.code === 'ECONNRESET' || e.code === 'EPIPE')
  );
}

interface PoolDeps {
  store: PinStore;
  timeoutMs: number;
  /** A certificate trusted on first use (audit it). */
  onTrust(m: MachineEntry, r: PinRecord): void;
  /** Idle connections closed after this; default `IDLE_TLS_MS` (tests shorten it). */
  idleMs?: number;
}

/** One machine's pool: every new connection is made and checked by `connectPinned`. */
class PinnedAgent extends https.Agent {
  /** The fingerprint its connections were checked against (null until the first one is). */
  verified: string | null = null;
  private retired = false;
  /** Connections checked against another pin than `verified`: used once, never kept. */
  private readonly usedOnce = new WeakSet<Duplex>();

  constructor(
    readonly m: MachineEntry,
    readonly origin: string,
    private readonly url: URL,
    private readonly deps: PoolDeps,
  ) {
    super({
      keepAlive: true,
      keepAliveMsecs: 1000,
      maxFreeSockets: MAX_IDLE_TLS,
      timeout: deps.idleMs ?? IDLE_TLS_MS,
      scheduling: 'lifo',
    });
  }

  override createConnection(
    _options: http.ClientRequestArgs,
    done?: (err: Error | null, socket: Duplex) => void,
  ): undefined {
    const m = this.m;
    connectPinned({
      machine: m,
      url: this.url,
      store: this.deps.store,
      timeoutMs: this.deps.timeoutMs,
      onTrust: (r) => this.deps.onTrust(m, r),
    }).then(
      (socket: TLSSocket) => {
        const got = fingerprintOf(socket.getPeerCertificate());
        this.verified ??= got;
        if (got !== this.verified) this.usedOnce.add(socket);
        done?.(null, socket);
      },
      (e: unknown) => done?.(e instanceof Error ? e : new Error(String(e)), undefined as unknown as Duplex),
    );
    return undefined;
  }

  override keepSocketAlive(socket: Duplex): boolean {
    if (this.retired || this.usedOnce.has(socket)) return false;
    return (super.keepSocketAlive(socket) as unknown as boolean | undefined) !== false;
  }

  /** No connection is used again: idle ones closed now, busy ones when their request ends. */
  retire(): void {
    this.retired = true;
    for (const list of Object.values(this.freeSockets)) for (const s of list ?? []) s.destroy();
  }
}

/** The gateway's pools of pinned TLS connections, by machine id. */
export class PinnedPools {
  private readonly pools = new Map<string, PinnedAgent>();
  private closed = false;

  constructor(private readonly deps: PoolDeps) {}

  /**
   * The machine's pool for a read to `url`. A kept connection is used only while the pin in
   * force (configured, else the pin file, read again now) is the one it was checked against:
   * otherwise the pool is retired and a new one checks its connections against the pin now.
   * Throws `PinFileError` (the pool retired: a broken pin file trusts no connection).
   */
  agentFor(m: MachineEntry, url: URL): http.Agent {
    const old = this.pools.get(m.id);
    let pin: string | null;
    try {
      pin =
        m.tlsFingerprint !== undefined
          ? normalizeFingerprint(m.tlsFingerprint)
          : (this.deps.store.get(m.id)?.fingerprint ?? null);
    } catch (e) {
      this.drop(m.id);
      throw e;
    }
    if (old && old.m === m && old.origin === url.origin && (old.verified === null || old.verified === pin))
      return old;
    old?.retire();
    const agent = new PinnedAgent(m, url.origin, url, this.deps);
    // The gateway stopped: a request still sent gets a connection, never kept.
    if (this.closed) agent.retire();
    else this.pools.set(m.id, agent);
    return agent;
  }

  /** The machine's kept connections are not used again (its pin was forgotten, it was removed). */
  drop(id: string): void {
    this.pools.get(id)?.retire();
    this.pools.delete(id);
  }

  /** Gateway stop: every connection closed, busy or idle. */
  close(): void {
    this.closed = true;
    for (const a of this.pools.values()) {
      a.retire();
      a.destroy();
    }
    this.pools.clear();
  }
}
