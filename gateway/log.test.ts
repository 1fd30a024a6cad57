import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { createLogger as createServerLogger } from '../server/log';
import { createLogger, loggerFromEnv, Reachability, unreachableReason, type LogLevel } from './log';
import type { MachineEntry } from './machines';
import { consoleFetch, openWs, startGateway, startStub, tempDir, testFamily } from './test-util';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  vi.restoreAllMocks();
  for (const c of cleanups.splice(0).reverse()) await c();
});

function sink(json: boolean) {
  const lines: Array<{ line: string; level: LogLevel }> = [];
  const now = () => new Date('2026-03-01T10:00:00.000Z');
  const write = (line: string, level: LogLevel) => lines.push({ line, level });
  return { lines, opts: { json, write, now } };
}

describe('gateway log lines', () => {
  it('are the server’s format: text, or one JSON object a line with time, level, msg and fields', () => {
    for (const json of [false, true]) {
      const ours = sink(json);
      const server = sink(json);
      const a = createLogger(ours.opts);
      const b = createServerLogger(server.opts);
      for (const l of [a, b]) {
        l.info('machine p1 online', { machine: 'p1', event: 'online' });
        l.warn('machine p1 offline: connection refused', {
          machine: 'p1',
          reason: 'connection refused',
          x: undefined,
        });
        l.error('could not write the audit log', { error: new Error('EACCES'), msg: 'not over msg' });
      }
      expect(ours.lines).toEqual(server.lines);
    }
    const j = sink(true);
    createLogger(j.opts).warn('machine p1 offline: no answer in time', { machine: 'p1' });
    expect(JSON.parse(j.lines[0]!.line)).toEqual({
      time: '2026-03-01T10:00:00.000Z',
      level: 'warn',
      msg: 'machine p1 offline: no answer in time',
      machine: 'p1',
    });
    expect(loggerFromEnv({ SHOPDECK_LOG: 'json' }).json).toBe(true);
    expect(loggerFromEnv({}).json).toBe(false);
  });

  it('say once per machine when it goes offline and when it comes back', () => {
    const s = sink(false);
    const r = new Reachability(createLogger(s.opts));
    r.up('p1'); // answering from the start: nothing to say
    r.down('p1', 'connection refused');
    r.down('p1', 'connection refused');
    r.down('p2', 'no answer in time');
    r.up('p1');
    r.up('p1');
    expect(s.lines.map((l) => l.line)).toEqual([
      'shopdeck: warn: machine p1 offline: connection refused (machine=p1 event=offline reason="connection refused")',
      'shopdeck: warn: machine p2 offline: no answer in time (machine=p2 event=offline reason="no answer in time")',
      'shopdeck: machine p1 online (machine=p1 event=online)',
    ]);
    expect([r.status('p1'), r.status('p2'), r.status('p3')]).toEqual(['online', 'offline', 'unknown']);
    expect(unreachableReason({ code: 'ECONNREFUSED' }, false)).toBe('connection refused');
    expect(unreachableReason(new Error('the certificate changed'), false)).toBeNull();
  });
});

describe('machines going offline and online, as the gateway sees them', () => {
  async function freePort(): Promise<number> {
    const s = http.createServer();
    await new Promise<void>((r) => s.listen(0, '127.0.0.1', () => r()));
    const port = (s.address() as AddressInfo).port;
    await new Promise<void>((r) => s.close(() => r()));
    return port;
  }

  async function gateway(url: string, timeoutMs?: number) {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const lines: string[] = [];
    const m: MachineEntry = {
      id: 'p1',
      name: 'Printer 1',
      kind: 'prunt',
      simulated: false,
      url: new URL(url),
      wsUrl: null,
      secrets: {},
    };
    const gw = await startGateway({
      machines: { file: null, machines: [m] },
      families: { prunt: testFamily('prunt') },
      dataDir: t.dir,
      env: {},
      timeoutMs,
      log: createLogger({ json: true, write: (l) => lines.push(l) }),
    });
    cleanups.push(gw.close);
    const events = () =>
      lines
        .map((l) => JSON.parse(l) as { msg: string; event?: string })
        .filter((l) => l.event)
        .map((l) => l.msg);
    return { gw, events };
  }

  it('over HTTP: one line at the first failure, one at the first answer after', async () => {
    const port = await freePort();
    const { gw, events } = await gateway(`http://127.0.0.1:${port}`);
    expect((await consoleFetch(`${gw.url}/machines/p1/status`)).status).toBe(502);
    expect((await consoleFetch(`${gw.url}/machines/p1/status`)).status).toBe(502);
    expect(events()).toEqual(['machine p1 offline: connection refused']);
    const up = http.createServer((_req, res) => res.end('{}'));
    await new Promise<void>((r) => up.listen(port, '127.0.0.1', () => r()));
    cleanups.push(() => new Promise<void>((r) => up.close(() => r())));
    expect((await consoleFetch(`${gw.url}/machines/p1/status`)).status).toBe(200);
    expect((await consoleFetch(`${gw.url}/machines/p1/status`)).status).toBe(200);
    expect(events()).toEqual(['machine p1 offline: connection refused', 'machine p1 online']);
  });

  it('over WebSocket too', async () => {
    const port = await freePort();
    const { gw, events } = await gateway(`http://127.0.0.1:${port}`);
    await expect(openWs(`ws://${gw.host}/machines/p1/ws`)).rejects.toMatchObject({ status: 502 });
    expect(events()).toEqual(['machine p1 offline: connection refused']);
  });

  it('a controller that does not answer in time is offline; a browser that leaves is not the machine’s fault', async () => {
    const s = await startStub();
    cleanups.push(s.close);
    s.respond = () => undefined; // never answers
    const { gw, events } = await gateway(s.url, 300);
    const gone = new AbortController();
    const pending = consoleFetch(`${gw.url}/machines/p1/status`, { signal: gone.signal }).catch(() => null);
    await new Promise((r) => setTimeout(r, 50));
    gone.abort();
    await pending;
    await new Promise((r) => setTimeout(r, 50));
    expect(events()).toEqual([]);
    expect((await consoleFetch(`${gw.url}/machines/p1/status`)).status).toBe(504);
    expect(events()).toEqual(['machine p1 offline: no answer in time']);
  });

  it('the gateway writes JSON lines with SHOPDECK_LOG=json', async () => {
    const port = await freePort();
    const written: string[] = [];
    vi.spyOn(process.stderr, 'write').mockImplementation((chunk: string | Uint8Array) => {
      written.push(String(chunk));
      return true;
    });
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          {
            id: 'p1',
            name: 'p1',
            kind: 'prunt',
            simulated: false,
            url: new URL(`http://127.0.0.1:${port}`),
            wsUrl: null,
            secrets: {},
          },
        ],
      },
      families: { prunt: testFamily('prunt') },
      dataDir: t.dir,
      env: { SHOPDECK_LOG: 'json' },
    });
    cleanups.push(gw.close);
    await consoleFetch(`${gw.url}/machines/p1/status`);
    const line = written.find((l) => l.includes('offline'));
    expect(JSON.parse(line ?? 'null')).toMatchObject({
      level: 'warn',
      msg: 'machine p1 offline: connection refused',
      machine: 'p1',
      reason: 'connection refused',
      time: expect.any(String),
    });
  });
});
