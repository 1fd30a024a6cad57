import net from 'node:net';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import type { FamilyDescriptor, SharingHints } from '../src/fleet/contract';
import type { MachineEntry } from './machines';
import { consoleFetch, startGateway, tempDir, testFamily, type Running } from './test-util';

/**
 * Issue 15: when the controller's connection breaks partway through an answer, the gateway ends
 * the browser's response at once, as an error — never as a whole answer, never left open. Real
 * sockets: a raw TCP controller that writes a status line, headers and 20 bytes of body, then
 * breaks the connection or falls silent.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

type Fault =
  'reset-length' | 'reset-chunked' | 'fin-length' | 'fin-chunked' | 'silent-length' | 'silent-chunked';

/** 20 bytes of a JSON answer that never ends. */
const PART = '{"progress":12.5,"w';

interface RawController {
  url: string;
  /** Request lines received. */
  lines: string[];
  fault: Fault | 'whole';
  close(): Promise<void>;
}

async function rawController(): Promise<RawController> {
  const sockets = new Set<net.Socket>();
  const ctl: RawController = { url: '', lines: [], fault: 'whole', close: async () => undefined };
  const server = net.createServer((s) => {
    sockets.add(s);
    s.on('close', () => sockets.delete(s));
    s.on('error', () => undefined);
    let buf = '';
    s.on('data', (d: Buffer) => {
      buf += d.toString('latin1');
      const end = buf.indexOf('\r\n\r\n');
      if (end < 0) return;
      ctl.lines.push(buf.slice(0, buf.indexOf('\r\n')));
      buf = '';
      const fault = ctl.fault;
      if (fault === 'whole') {
        const body = '{"progress":12.5,"working":1}';
        s.write(
          `HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: ${body.length}\r\nConnection: close\r\n\r\n${body}`,
        );
        s.end();
        return;
      }
      const chunked = fault.endsWith('chunked');
      s.write(
        'HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n' +
          (chunked ? 'Transfer-Encoding: chunked\r\n\r\n' : 'Content-Length: 200\r\n\r\n') +
          (chunked ? `${PART.length.toString(16)}\r\n${PART}\r\n` : PART),
      );
      // reset: the connection breaks 20 ms later; fin: it is closed 20 ms later (half-close, as a
      // proxy that gives up does); silent: nothing more, ever (until the test ends).
      if (fault.startsWith('reset')) setTimeout(() => s.destroy(), 20);
      if (fault.startsWith('fin')) setTimeout(() => s.end(), 20);
    });
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  ctl.url = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
  ctl.close = async () => {
    for (const s of sockets) s.destroy();
    await new Promise<void>((r) => server.close(() => r()));
  };
  cleanups.push(ctl.close);
  return ctl;
}

function entry(id: string, url: string, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id,
    name: id,
    kind: 'prunt',
    simulated: false,
    url: new URL(url),
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

function family(sharing: SharingHints | undefined): FamilyDescriptor {
  const base = testFamily('prunt');
  return { ...base, gateway: { ...base.gateway, sharing } };
}

async function setup(m: MachineEntry, fam: FamilyDescriptor, timeoutMs: number): Promise<Running> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const gw = await startGateway({
    machines: { file: null, machines: [m] },
    families: { prunt: fam },
    dataDir: t.dir,
    env: {},
    timeoutMs,
  });
  cleanups.push(gw.close);
  return gw;
}

/**
 * What the browser gets: the status (0: the request itself failed, no answer at all), how its body
 * read ended (`whole` with the text, or `error`), and when — or `open` when the body was still
 * open after `waitMs`. A cut answer may reach the browser either way: as a failed request (a
 * shared read's answer is sent only once whole) or as a body that ends in an error.
 */
async function browserRead(
  url: string,
  init: RequestInit,
  waitMs: number,
): Promise<{ status: number; body: 'whole' | 'error' | 'open'; text: string; ms: number }> {
  const t0 = Date.now();
  const ctrl = new AbortController();
  let timer: ReturnType<typeof setTimeout> | undefined;
  const late = new Promise<{ body: 'open'; text: string }>((resolve) => {
    timer = setTimeout(() => resolve({ body: 'open', text: '' }), waitMs);
  });
  let r: Response;
  try {
    const answered = await Promise.race([consoleFetch(url, { ...init, signal: ctrl.signal }), late]);
    if (!(answered instanceof Response)) {
      ctrl.abort();
      return { status: 0, body: 'open', text: '', ms: Date.now() - t0 };
    }
    r = answered;
  } catch {
    clearTimeout(timer);
    return { status: 0, body: 'error', text: '', ms: Date.now() - t0 };
  }
  const read = r.text().then(
    (text) => ({ body: 'whole' as const, text }),
    () => ({ body: 'error' as const, text: '' }),
  );
  const got = await Promise.race([read, late]);
  clearTimeout(timer);
  if (got.body === 'open') ctrl.abort();
  return { status: r.status, ...got, ms: Date.now() - t0 };
}

const sharings: Array<[string, SharingHints | undefined]> = [
  ['not shared', undefined],
  ['shared', { shareRead: () => 500, keepAlive: false, maxConcurrentReads: 2 }],
  ['shared, kept-alive connections', { shareRead: () => 500, keepAlive: true, maxConcurrentReads: 2 }],
];

describe('a cut answer ends the browser’s response at once, as an error', () => {
  for (const [name, sharing] of sharings) {
    for (const fault of ['reset-length', 'reset-chunked', 'fin-length', 'fin-chunked'] as const) {
      it(`${name}: the controller breaks the connection after 20 bytes (${fault})`, async () => {
        const ctl = await rawController();
        const gw = await setup(entry('p1', ctl.url), family(sharing), 5000);
        ctl.fault = fault;
        const got = await browserRead(`${gw.url}/machines/p1/progress`, {}, 3000);
        expect(got.body).toBe('error');
        expect(got.ms).toBeLessThan(2000);
        // Whole again: the next read is whole (nothing of the cut one was kept).
        ctl.fault = 'whole';
        const next = await browserRead(`${gw.url}/machines/p1/progress`, {}, 3000);
        expect(next).toMatchObject({ status: 200, body: 'whole', text: '{"progress":12.5,"working":1}' });
      });
    }

    for (const fault of ['silent-length', 'silent-chunked'] as const) {
      it(`${name}: the controller falls silent after 20 bytes (${fault}): the gateway's timeout covers the body`, async () => {
        const ctl = await rawController();
        const gw = await setup(entry('p1', ctl.url), family(sharing), 300);
        ctl.fault = fault;
        const got = await browserRead(`${gw.url}/machines/p1/progress`, {}, 3000);
        expect(got.body).toBe('error');
        expect(got.ms).toBeLessThan(1500);
      });
    }
  }

  it('with the machine’s secrets redacted on the way (the answer passes a transform): still cut at once', async () => {
    const ctl = await rawController();
    const gw = await setup(
      entry('p1', ctl.url, { secrets: { apiKey: 'K3y-0f-the-ctrl-77' } }),
      family(undefined),
      5000,
    );
    ctl.fault = 'reset-chunked';
    const got = await browserRead(`${gw.url}/machines/p1/progress`, {}, 3000);
    expect(got.body).toBe('error');
    expect(got.ms).toBeLessThan(2000);
  });

  it('a command whose answer is cut is audited as not confirmed, and the browser’s answer ends as an error', async () => {
    const ctl = await rawController();
    const gw = await setup(entry('p1', ctl.url), family(undefined), 5000);
    ctl.fault = 'reset-length';
    const got = await browserRead(`${gw.url}/machines/p1/job?action=pause`, {}, 3000);
    expect(got.body).toBe('error');
    const entryOf = (): { result: string; error?: string } | undefined =>
      gw.gw.audit.all().find((e) => e.type === 'command');
    const until = Date.now() + 2000;
    while (!entryOf() && Date.now() < until) await new Promise((r) => setTimeout(r, 10));
    expect(entryOf()).toMatchObject({ result: 'error' });
    expect(entryOf()?.error).toMatch(/not confirmed/);
    expect(entryOf()?.error).toMatch(/cut/);
  });
});
