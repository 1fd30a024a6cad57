import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { createLogger as createServerLogger } from '../server/log';
import type { WatchSummary } from '../src/fleet/contract';
import {
  createLogger,
  escapeControls,
  loggerFromEnv,
  Reachability,
  unreachableReason,
  type LogLevel,
} from './log';
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

  it('go once each to their level (info on stdout, warnings and errors on stderr), JSON fully escaped', () => {
    for (const json of [false, true]) {
      const s = sink(json);
      const l = createLogger(s.opts);
      l.info('i');
      l.warn('w');
      l.error('e');
      expect(s.lines.map((x) => x.level)).toEqual(['info', 'warn', 'error']);
    }
    const out = vi.spyOn(process.stdout, 'write').mockImplementation(() => true);
    const err = vi.spyOn(process.stderr, 'write').mockImplementation(() => true);
    const l = createLogger({ now: () => new Date(0) });
    l.info('to stdout');
    l.warn('to stderr');
    expect(out.mock.calls.map((c) => c[0])).toEqual(['shopdeck: to stdout\n']);
    expect(err.mock.calls.map((c) => c[0])).toEqual(['shopdeck: warn: to stderr\n']);
    out.mockRestore();
    err.mockRestore();

    // DEL, C1 and the line separators (left as they are by JSON) are escaped too; the JSON reads back.
    const j = sink(true);
    const text = 'a\u007f\u0085\u009b2J\u2028\u2029\n\u001bz';
    createLogger(j.opts).info(text, { [text]: { nested: text } });
    const line = j.lines[0]?.line ?? '';
    // eslint-disable-next-line no-control-regex
    expect(line).not.toMatch(/[\u0000-\u001f\u007f-\u009f\u2028\u2029]/);
    expect(JSON.parse(line)).toEqual({
      level: 'info',
      time: '2026-03-01T10:00:00.000Z',
      msg: text,
      [text]: { nested: text },
    });
  });

  it('a field that refers to itself is written, not thrown (a log call never breaks its caller)', () => {
    for (const json of [false, true]) {
      const s = sink(json);
      const loop: Record<string, unknown> = { id: 'p1' };
      loop.self = loop;
      expect(() => createLogger(s.opts).warn('odd', { loop })).not.toThrow();
      expect(s.lines).toHaveLength(1);
      expect(s.lines[0]?.line).toContain('"id":"p1"');
      expect(s.lines[0]?.line).toContain('[Circular]');
    }
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

describe('log injection (controller text in log lines)', () => {
  // An operator's upload named like this, a controller's alarm worded like this: each would
  // forge lines (or rewrite the operator's terminal) if written as it is.
  const JOB = 'part.gcode\nshopdeck: machine p1 online\r\u001b[2K\u001b]0;pwned\u0007';
  const ALARM = 'flame\r\nshopdeck: warn: FORGED alarm cleared\u2028\u009b2J\u007f';

  function watched(lines: string[], json: boolean, url: string) {
    const fam = testFamily('prunt');
    const family = {
      ...fam,
      gateway: {
        ...fam.gateway,
        sharing: {
          keepAlive: false,
          maxConcurrentReads: 2,
          watch: {
            everyMs: 40,
            poll: {
              path: '/status',
              read: (_status: number, body: string) => JSON.parse(body) as WatchSummary,
            },
          },
        },
      },
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    return startGateway({
      machines: {
        file: null,
        machines: [
          {
            id: 'p1',
            name: 'P',
            kind: 'prunt',
            simulated: false,
            url: new URL(url),
            wsUrl: null,
            secrets: {},
          },
        ],
      },
      families: { prunt: family },
      dataDir: t.dir,
      env: {},
      watch: true,
      log: createLogger({ json, write: (l) => lines.push(l) }),
    });
  }

  for (const json of [false, true]) {
    it(`a job name and an alarm with \\n, \\r and escape sequences make exactly one escaped line each (${json ? 'JSON' : 'text'})`, async () => {
      const s = await startStub();
      cleanups.push(s.close);
      s.respond = (_req, res) => {
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end(JSON.stringify({ state: 'running', job: JOB, alarm: ALARM }));
      };
      const lines: string[] = [];
      const gw = await watched(lines, json, s.url);
      cleanups.push(gw.close);
      const end = Date.now() + 8000;
      while (!lines.some((l) => l.includes('alarm')) && Date.now() < end)
        await new Promise((r) => setTimeout(r, 20));
      gw.gw.close();
      // Every write is one line: no line break, no terminal control of any kind.
      // eslint-disable-next-line no-control-regex
      for (const l of lines) expect(l).not.toMatch(/[\u0000-\u001f\u007f-\u009f\u2028\u2029]/);
      const started = lines.filter((l) => l.includes('job started'));
      const alarm = lines.filter((l) => l.includes('FORGED'));
      expect(started).toHaveLength(1);
      expect(alarm).toHaveLength(1);
      // Nothing the controller wrote starts a line of its own.
      expect(lines.filter((l) => /^shopdeck: machine p1 online|^shopdeck: warn: FORGED/.test(l))).toEqual([]);
      if (json) {
        // The JSON is valid and gives the text back exactly.
        expect((JSON.parse(started[0] ?? '') as { msg: string }).msg).toBe(`p1: job started (${JOB})`);
        expect((JSON.parse(alarm[0] ?? '') as { msg: string }).msg).toBe(`p1: alarm (${ALARM})`);
      } else {
        expect(started[0]).toBe(
          'shopdeck: p1: job started (part.gcode\\nshopdeck: machine p1 online\\r\\u001b[2K\\u001b]0;pwned\\u0007) (machine=p1 event="job started")',
        );
        expect(alarm[0]).toContain('flame\\r\\nshopdeck: warn: FORGED alarm cleared\\u2028\\u009b2J\\u007f');
      }
    });
  }

  it('escapes field values and the start banner too, in both loggers', () => {
    for (const make of [createLogger, createServerLogger]) {
      const s = sink(false);
      const l = make(s.opts);
      l.error('upload failed', { file: 'a\u001b[31mb', user: 'x\ny' });
      createServerLogger(s.opts).banner('listening', 'Shopdeck\n  machines: 2 from m\u001b[2J.json', {});
      expect(s.lines.map((x) => x.line)).toEqual([
        'shopdeck: error: upload failed (file=a\\u001b[31mb user="x\\ny")',
        'Shopdeck\n  machines: 2 from m\\u001b[2J.json',
      ]);
    }
    expect(escapeControls('\t\u0000')).toBe('\\t\\u0000');
  });
});
