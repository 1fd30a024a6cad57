import { createHash, randomBytes } from 'node:crypto';
import {
  closeSync,
  fsyncSync,
  mkdirSync,
  openSync,
  readFileSync,
  renameSync,
  rmSync,
  statSync,
  writeSync,
  type Stats,
} from 'node:fs';
import net from 'node:net';
import path from 'node:path';
import tls from 'node:tls';
import { z } from 'zod';
import { MACHINE_ID } from '../src/fleet/types';
import { normalizeFingerprint, type MachineEntry } from './machines';

/**
 * Certificate pinning for controllers reached over TLS (TouchCut serves HTTPS with a
 * self-signed certificate, so the usual CA check cannot be used and `rejectUnauthorized` is
 * off). Instead each machine's certificate is pinned by its SHA-256 fingerprint:
 *
 * 1. `tlsFingerprint` in the machines file, when set, is the only certificate accepted;
 * 2. otherwise the pin remembered in `<data>/tls-pins.json`;
 * 3. otherwise the first certificate seen is trusted and remembered (trust on first use).
 *
 * The check runs on `secureConnect`, before the caller gets the socket, so nothing (no request
 * line, no `X-TouchCut-API-Key`) is ever written to a controller that fails it. A pin covers
 * every TLS address of the machine (`url` and `wsUrl`): a controller has one certificate.
 * Expiry and names are not checked: the fingerprint is the whole trust.
 *
 * A supervisor gets a controller's fingerprint from its screen or with
 * `openssl s_client -connect <host>:443 </dev/null | openssl x509 -noout -fingerprint -sha256`.
 *
 * Used by `proxy-forward.ts` and `upstream-request.ts` (a command's or a lone request's own
 * socket, `createConnection: () => socket`), `tls-pool.ts` (reads' kept connections, made here)
 * and `controller-socket.ts` (`wss:`). A rejection (`CertificateChanged`, `PinFileError`, a
 * network error) is a 502 with its message; `onTrust` is audited (`tls-trust`). `GET /api/tls`
 * and `DELETE /api/tls/<id>` (supervisors, routes/tls.ts) list and forget pins (gateway/README.md).
 */

export { normalizeFingerprint };

export const PIN_FILE = 'tls-pins.json';

/** One remembered certificate, as stored in `tls-pins.json` under the machine id. */
export interface PinRecord {
  /** SHA-256 of the certificate (DER), "AB:CD:…" */
  fingerprint: string;
  /** ISO time it was first trusted */
  firstSeen: string;
  /** Certificate subject, "CN=kineticcutter, O=…" */
  subject?: string;
  /** End of validity, ISO time (shown only: pinning ignores expiry) */
  validTo?: string;
}

const FINGERPRINT = /^[0-9A-F]{2}(:[0-9A-F]{2}){31}$/;

const pinFileSchema = z.record(
  z.string().regex(MACHINE_ID, 'a key is not a machine id'),
  z.object({
    fingerprint: z.string().regex(FINGERPRINT, 'not a SHA-256 fingerprint "AB:CD:…"'),
    firstSeen: z.string(),
    subject: z.string().optional(),
    validTo: z.string().optional(),
  }),
);

/** The pin file exists but cannot be used. Nothing is trusted until it is fixed. */
export class PinFileError extends Error {
  constructor(
    readonly file: string,
    readonly problem: string,
  ) {
    super(
      `Shopdeck: the TLS pin file ${file} is not valid (${problem}); no TLS controller is trusted until it is fixed. ` +
        `Repair it, or delete it to trust every controller's current certificate again on first use.`,
    );
    this.name = 'PinFileError';
  }
}

/** The controller showed another certificate than the configured or remembered one. */
export class CertificateChanged extends Error {
  constructor(
    readonly machineId: string,
    readonly machineName: string,
    readonly expected: string,
    readonly got: string,
    /** Where `expected` came from. */
    readonly source: 'configured' | 'pinned',
  ) {
    const who = machineName && machineName !== machineId ? `${machineName} (${machineId})` : machineId;
    const how =
      source === 'configured'
        ? `puts the new fingerprint in the machines file (field "tlsFingerprint" of "${machineId}") after reading it on the controller itself`
        : `accepts the new certificate (Supervisor › TLS certificates › Forget, i.e. DELETE /api/tls/${machineId}; the next connection trusts the certificate it is shown)`;
    super(
      `the certificate of ${who} changed: expected ${expected}, got ${got} — ` +
        `if the controller was replaced or re-keyed, a supervisor ${how}; ` +
        `otherwise someone may be impersonating it. Nothing was sent to it.`,
    );
    this.name = 'CertificateChanged';
  }
}

function stampOf(st: Stats): string {
  return `${st.mtimeMs}:${st.size}:${st.ino}`;
}

function errCode(e: unknown): string | undefined {
  return e && typeof e === 'object' && 'code' in e ? String((e as { code: unknown }).code) : undefined;
}

/**
 * The trusted-on-first-use pins, `<dataDir>/tls-pins.json`:
 * `{ "<machineId>": { "fingerprint": "AA:BB:…", "firstSeen": "<ISO>", "subject"?, "validTo"? } }`.
 *
 * Loaded on first use and again whenever the file changes on disk (so a pin removed by hand
 * counts at once); written atomically (temporary file + rename). A missing file is empty; a
 * file that is not valid throws `PinFileError` from every method and is never overwritten:
 * a broken pin file must not quietly turn into "trust whatever shows up".
 */
export class PinStore {
  readonly file: string;
  private cache: { stamp: string; pins: Map<string, PinRecord> } | null = null;

  constructor(readonly dataDir: string) {
    this.file = path.join(dataDir, PIN_FILE);
  }

  private load(): Map<string, PinRecord> {
    let st: Stats;
    try {
      st = statSync(this.file);
    } catch (e) {
      if (errCode(e) !== 'ENOENT') throw new PinFileError(this.file, `cannot read it: ${String(e)}`);
      if (this.cache?.stamp !== 'absent') this.cache = { stamp: 'absent', pins: new Map() };
      return this.cache.pins;
    }
    const stamp = stampOf(st);
    if (this.cache?.stamp === stamp) return this.cache.pins;
    let text: string;
    try {
      text = readFileSync(this.file, 'utf8');
    } catch (e) {
      throw new PinFileError(this.file, `cannot read it: ${String(e)}`);
    }
    let data: unknown;
    try {
      data = JSON.parse(text) as unknown;
    } catch (e) {
      throw new PinFileError(this.file, `not JSON: ${e instanceof Error ? e.message : String(e)}`);
    }
    if (!data || typeof data !== 'object' || Array.isArray(data))
      throw new PinFileError(
        this.file,
        'expected an object { "<machine id>": { "fingerprint", "firstSeen" } }',
      );
    // Checked before zod, which would drop a "__proto__" key instead of refusing it.
    const badKey = Object.keys(data).find((k) => !MACHINE_ID.test(k));
    if (badKey !== undefined) throw new PinFileError(this.file, `"${badKey}": not a machine id`);
    const r = pinFileSchema.safeParse(data);
    if (!r.success) {
      const i = r.error.issues[0];
      const where = i && i.path.length ? `"${i.path.map(String).join('.')}"` : 'top level';
      throw new PinFileError(this.file, `${where}: ${i?.message ?? 'invalid'}`);
    }
    const pins = new Map<string, PinRecord>();
    for (const [id, p] of Object.entries(r.data)) {
      const rec: PinRecord = { fingerprint: p.fingerprint, firstSeen: p.firstSeen };
      if (p.subject !== undefined) rec.subject = p.subject;
      if (p.validTo !== undefined) rec.validTo = p.validTo;
      pins.set(id, rec);
    }
    this.cache = { stamp, pins };
    return pins;
  }

  private save(pins: Map<string, PinRecord>): void {
    mkdirSync(this.dataDir, { recursive: true });
    const obj: Record<string, PinRecord> = {};
    for (const id of [...pins.keys()].sort()) obj[id] = pins.get(id)!;
    const text = JSON.stringify(obj, null, 2) + '\n';
    const tmp = `${this.file}.${process.pid}.${randomBytes(6).toString('hex')}.tmp`;
    try {
      const fd = openSync(tmp, 'wx', 0o644);
      try {
        writeSync(fd, text);
        fsyncSync(fd);
      } finally {
        closeSync(fd);
      }
      renameSync(tmp, this.file);
    } catch (e) {
      rmSync(tmp, { force: true });
      throw e;
    }
    this.cache = { stamp: stampOf(statSync(this.file)), pins };
  }

  /** The pin of a machine, or null. Throws PinFileError when the file is broken. */
  get(id: string): PinRecord | null {
    const p = this.load().get(id);
    return p ? { ...p } : null;
  }

  /**
   * Pins a certificate. Keeps the existing record (and its firstSeen) when the same
   * fingerprint is already pinned; refuses to replace a different one: `forget` it first.
   */
  remember(
    id: string,
    info: { fingerprint: string; subject?: string; validTo?: string; firstSeen?: string },
  ): PinRecord {
    if (!MACHINE_ID.test(id)) throw new Error(`"${id}" is not a machine id`);
    const fingerprint = normalizeFingerprint(info.fingerprint);
    if (!fingerprint) throw new Error(`"${info.fingerprint}" is not a SHA-256 fingerprint`);
    const pins = this.load();
    const old = pins.get(id);
    if (old) {
      if (old.fingerprint === fingerprint) return { ...old };
      throw new Error(
        `${id} is already pinned to ${old.fingerprint}; forget that pin before trusting ${fingerprint}`,
      );
    }
    const rec: PinRecord = { fingerprint, firstSeen: info.firstSeen ?? new Date().toISOString() };
    if (info.subject !== undefined) rec.subject = info.subject;
    if (info.validTo !== undefined) rec.validTo = info.validTo;
    const next = new Map(pins);
    next.set(id, rec);
    this.save(next);
    return { ...rec };
  }

  /** Removes a pin (a supervisor accepts a changed certificate). Returns what was removed. */
  forget(id: string): PinRecord | null {
    const pins = this.load();
    const old = pins.get(id);
    if (!old) return null;
    const next = new Map(pins);
    next.delete(id);
    this.save(next);
    return { ...old };
  }

  /** Every pin, by machine id. */
  list(): Array<{ id: string } & PinRecord> {
    return [...this.load()]
      .map(([id, p]) => ({ id, ...p }))
      .sort((a, b) => (a.id < b.id ? -1 : a.id > b.id ? 1 : 0));
  }
}

/** SHA-256 of the certificate's DER, "AB:CD:…" (the same as `cert.fingerprint256`). */
export function fingerprintOf(cert: Pick<tls.PeerCertificate, 'raw'>): string {
  const hex = createHash('sha256').update(cert.raw).digest('hex').toUpperCase();
  return hex.match(/../g)!.join(':');
}

function describeSubject(cert: tls.PeerCertificate): string | undefined {
  const subject: tls.Certificate | undefined = cert.subject;
  if (!subject) return undefined;
  const parts = Object.entries(subject)
    .filter((e): e is [string, string | string[]] => e[1] !== undefined)
    .map(([k, v]) => `${k}=${Array.isArray(v) ? v.join('+') : v}`);
  return parts.length ? parts.join(', ').slice(0, 300) : undefined;
}

function isoOf(date: string | undefined): string | undefined {
  if (!date) return undefined;
  const t = Date.parse(date);
  return Number.isNaN(t) ? date : new Date(t).toISOString();
}

export interface ConnectPinnedOptions {
  /** The machine (its `tlsFingerprint`, when configured, wins over the pin file). */
  machine: Pick<MachineEntry, 'id' | 'name' | 'tlsFingerprint'>;
  /** Where to connect: an `https:` or `wss:` URL (only host and port are used). */
  url: URL;
  store: PinStore;
  /** TCP connect + TLS handshake must finish within this. Default 15000 ms. */
  timeoutMs?: number;
  /** Called once when a certificate is trusted on first use (audit it). */
  onTrust?: (record: PinRecord & { id: string }) => void;
}

/**
 * Opens a TLS connection to a controller and resolves with the socket only once its
 * certificate matches `machine.tlsFingerprint`, else the stored pin, else once it has been
 * pinned (trust on first use). Nothing has been written on it: pass it to
 * `http.request({ …, createConnection: () => socket })` or
 * `new WebSocket(url, { createConnection: () => socket })` (see the top of this file).
 * Rejects with `CertificateChanged` (socket destroyed), `PinFileError`, or the network error.
 */
export function connectPinned(opts: ConnectPinnedOptions): Promise<tls.TLSSocket> {
  const { machine, url, store } = opts;
  const timeoutMs = opts.timeoutMs ?? 15_000;
  return new Promise<tls.TLSSocket>((resolve, reject) => {
    if (url.protocol !== 'https:' && url.protocol !== 'wss:') {
      reject(new Error(`connectPinned: ${url.protocol} is not a TLS address (https: or wss:)`));
      return;
    }
    let configured: string | null = null;
    if (machine.tlsFingerprint !== undefined) {
      configured = normalizeFingerprint(machine.tlsFingerprint);
      if (!configured) {
        reject(new Error(`the tlsFingerprint of ${machine.id} is not a SHA-256 fingerprint`));
        return;
      }
    }
    const host = url.hostname.replace(/^\[|\]$/g, '');
    const port = Number(url.port || 443);
    const socket = tls.connect({
      host,
      port,
      // SNI only for names: RFC 6066 forbids IP addresses there.
      ...(net.isIP(host) === 0 ? { servername: host } : {}),
      // Self-signed controllers: the CA check cannot pass; the pin below replaces it.
      rejectUnauthorized: false,
      ALPNProtocols: ['http/1.1'],
    });
    let settled = false;
    const fail = (e: Error): void => {
      if (settled) return;
      settled = true;
      clearTimeout(timer);
      socket.destroy();
      reject(e);
    };
    const timer = setTimeout(() => {
      const e = new Error(
        `TLS connection to ${host}:${port} (${machine.id}) timed out after ${timeoutMs} ms`,
      ) as Error & { code?: string };
      e.code = 'ETIMEDOUT';
      fail(e);
    }, timeoutMs);
    socket.once('error', fail);
    socket.once('secureConnect', () => {
      if (settled) return;
      const cert = socket.getPeerCertificate();
      if (!cert || !cert.raw || cert.raw.length === 0) {
        fail(new Error(`the controller of ${machine.id} presented no certificate`));
        return;
      }
      const got = fingerprintOf(cert);
      let expected: string;
      let source: 'configured' | 'pinned';
      try {
        if (configured) {
          expected = configured;
          source = 'configured';
        } else {
          const pin = store.get(machine.id);
          if (!pin) {
            const rec = store.remember(machine.id, {
              fingerprint: got,
              subject: describeSubject(cert),
              validTo: isoOf(cert.valid_to),
            });
            opts.onTrust?.({ id: machine.id, ...rec });
            expected = rec.fingerprint;
          } else {
            expected = pin.fingerprint;
          }
          source = 'pinned';
        }
      } catch (e) {
        fail(e instanceof Error ? e : new Error(String(e)));
        return;
      }
      if (got !== expected) {
        fail(new CertificateChanged(machine.id, machine.name, expected, got, source));
        return;
      }
      settled = true;
      clearTimeout(timer);
      socket.off('error', fail);
      // Until http/ws attaches its own listener, a late error must not crash the gateway.
      socket.on('error', () => undefined);
      resolve(socket);
    });
  });
}

/** What a supervisor page shows about one machine's certificate. */
export interface TlsPinView {
  id: string;
  name: string;
  /**
   * configured: `tlsFingerprint` in the machines file (the pin file is ignored);
   * pinned: trusted on first use; unpinned: no TLS connection yet, the next one is trusted.
   */
  mode: 'configured' | 'pinned' | 'unpinned';
  /** The fingerprint in force, null when unpinned. */
  fingerprint: string | null;
  /** The remembered pin (also listed when a configured fingerprint overrides it). */
  pin: PinRecord | null;
  /** Whether `DELETE /api/tls/<id>` means anything (not when the machines file decides). */
  canForget: boolean;
}

/** True when the gateway reaches this machine over TLS (`https:` url or `wss:` socket). */
export function usesTls(m: Pick<MachineEntry, 'simulated' | 'url' | 'wsUrl'>): boolean {
  return !m.simulated && (m.url?.protocol === 'https:' || m.wsUrl?.protocol === 'wss:');
}

/**
 * The certificate state of a machine for the API, or null when it is not reached over TLS.
 * No address is included. Throws PinFileError when the pin file is broken.
 */
export function pinInfo(
  m: Pick<MachineEntry, 'id' | 'name' | 'simulated' | 'url' | 'wsUrl' | 'tlsFingerprint'>,
  store: PinStore,
): TlsPinView | null {
  if (!usesTls(m)) return null;
  const pin = store.get(m.id);
  const configured = m.tlsFingerprint === undefined ? null : normalizeFingerprint(m.tlsFingerprint);
  if (configured) {
    return { id: m.id, name: m.name, mode: 'configured', fingerprint: configured, pin, canForget: false };
  }
  return {
    id: m.id,
    name: m.name,
    mode: pin ? 'pinned' : 'unpinned',
    fingerprint: pin?.fingerprint ?? null,
    pin,
    canForget: pin !== null,
  };
}

/** `pinInfo` of every machine reached over TLS, in the machines file's order (`GET /api/tls`). */
export function listPins(
  machines: ReadonlyArray<
    Pick<MachineEntry, 'id' | 'name' | 'simulated' | 'url' | 'wsUrl' | 'tlsFingerprint'>
  >,
  store: PinStore,
): TlsPinView[] {
  return machines.map((m) => pinInfo(m, store)).filter((v): v is TlsPinView => v !== null);
}
