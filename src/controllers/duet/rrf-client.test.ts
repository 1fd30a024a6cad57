import { http, HttpResponse } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { machineBase } from '../../fleet/origin';
import { DuetClient } from './client';

/**
 * The standalone client against answers shaped as the OpenAPI file and NOTES.md record them
 * (`{key, flags, result}`, `{"buff":n}`, `{err}`), and against hostile ones: every byte from a
 * board is untrusted.
 */

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => server.resetHandlers());
afterAll(() => server.close());

const base = machineBase('rc');

/** A standalone board answering rr_model from `parts` (seqs included) and recording requests. */
function board(parts: Record<string, unknown>, opts: { reply?: string } = {}) {
  const seen: string[] = [];
  server.use(
    http.get(`${base}/machine/connect`, () =>
      HttpResponse.json({ err: 0, apiLevel: 2, sessionTimeout: 8000 }),
    ),
    http.get(`${base}/rr_model`, ({ request }) => {
      const u = new URL(request.url);
      seen.push(`${u.searchParams.get('key')}|${u.searchParams.get('flags')}`);
      const key = u.searchParams.get('key') ?? '';
      const flags = u.searchParams.get('flags') ?? '';
      const result = key === '' ? { state: parts['state'], seqs: parts['seqs'] } : (parts[key] ?? null);
      return HttpResponse.json({ key, flags, result });
    }),
    // The gateway's rr_reply (replies.ts): no messages, no replies unless a test says.
    http.get(`${base}/rr_reply`, () =>
      HttpResponse.json({ next: 0, messages: opts.reply ? [opts.reply] : [], replies: {} }),
    ),
  );
  return seen;
}

async function connected(): Promise<DuetClient> {
  const c = new DuetClient('rc');
  await c.connect();
  expect(c.api).toBe('standalone');
  return c;
}

describe('RrfClient (standalone rr_*)', () => {
  it('reads every part at first, then only parts whose seqs moved; live parts are merged', async () => {
    const parts: Record<string, unknown> = {
      state: { status: 'idle', upTime: 1 },
      heat: { heaters: [{ current: 20 }] },
      volumes: [{ freeSpace: 1 }],
      seqs: { heat: 1, volumes: 1, reply: 0, volChanges: [0] },
    };
    const seen = board(parts);
    const c = await connected();
    const m1 = await c.rrf.poll();
    expect(seen).toEqual(['|d99fn', 'heat|d99vno', 'volumes|d99vno', 'limits|d99vno']);
    expect(m1['heat']).toEqual({ heaters: [{ current: 20 }] });
    seen.length = 0;
    parts['state'] = { status: 'processing' };
    parts['volumes'] = [{ freeSpace: 2 }];
    parts['seqs'] = { heat: 1, volumes: 2, reply: 0, volChanges: [1] };
    const m2 = await c.rrf.poll();
    expect(seen).toEqual(['|d99fn', 'volumes|d99vno']);
    expect(m2['state']).toEqual({ status: 'processing', upTime: 1 }); // merged, not replaced
    expect(m2['volumes']).toEqual([{ freeSpace: 2 }]);
    expect(m2['heat']).toBe(m1['heat']); // untouched parts are the same objects
  });

  it('takes no hostile part names from seqs, and at most 40 parts a poll', async () => {
    const seqs: Record<string, number> = { __proto__x: 1, 'a.b': 1, reply: 0 };
    for (let i = 0; i < 100; i++) seqs[`p${i}`] = 1;
    const raw = JSON.parse(`{"constructor":1,"__proto__":1,${JSON.stringify(seqs).slice(1)}`) as Record<
      string,
      unknown
    >;
    const seen = board({ state: {}, seqs: raw });
    const c = await connected();
    const m = await c.rrf.poll();
    const fetched = seen.filter((s) => s.endsWith('|d99vno')).map((s) => s.split('|')[0]);
    expect(fetched).not.toContain('__proto__');
    expect(fetched).not.toContain('constructor');
    expect(fetched).not.toContain('a.b');
    expect(fetched.length).toBeLessThanOrEqual(41);
    expect(Object.getPrototypeOf(m)).toBe(Object.prototype);
  });

  it('refuses a model nested deeper than 64 levels and a live model that is no object', async () => {
    let deep: unknown = 1;
    for (let i = 0; i < 70; i++) deep = { a: deep };
    board({ state: deep, seqs: {} });
    const c = await connected();
    await expect(c.rrf.poll()).rejects.toMatchObject({ kind: 'protocol' });
    server.use(http.get(`${base}/rr_model`, () => HttpResponse.json({ key: '', flags: '', result: [1, 2] })));
    await expect(c.rrf.poll()).rejects.toBeInstanceOf(LinkError);
    server.use(http.get(`${base}/rr_model`, () => new HttpResponse('{"key":', { status: 200 })));
    await expect(c.rrf.poll()).rejects.toBeInstanceOf(LinkError);
  });

  it('through the gateway: a code gets the reply of its own ticket, the board’s messages come from the feed once, the page never reads the board’s buffer', async () => {
    const parts: Record<string, unknown> = { state: {}, seqs: { reply: 5 } };
    board(parts);
    const codes: string[] = [];
    const asks: string[] = [];
    let head = 3;
    const messages: Array<{ id: number; text: string }> = [];
    const replies = new Map<string, string>();
    server.use(
      http.get(`${base}/rr_gcode`, ({ request }) => {
        codes.push(new URL(request.url).searchParams.get('gcode') ?? '');
        parts['seqs'] = { reply: 6 };
        replies.set('t-1', 'FIRMWARE_NAME: RepRapFirmware');
        return HttpResponse.json({ buff: 250, replyTicket: 't-1' });
      }),
      http.get(`${base}/rr_reply`, ({ request }) => {
        const q = new URL(request.url).searchParams;
        asks.push(q.toString());
        const after = q.get('after');
        const out: Record<string, string> = {};
        for (const t of q.getAll('ticket')) {
          const r = replies.get(t);
          if (r !== undefined) out[t] = r;
          replies.delete(t);
        }
        return HttpResponse.json({
          next: head,
          messages: after === null ? [] : messages.filter((m) => m.id > Number(after)).map((m) => m.text),
          replies: out,
        });
      }),
    );
    const c = await connected();
    const logged: string[] = [];
    c.rrf.onReply = (t) => logged.push(t);
    await c.rrf.poll();
    // The first ask only learns where the messages stand.
    expect(asks).toEqual(['']);
    c.kick = () => void c.rrf.poll();
    expect(await c.code('M115')).toBe('FIRMWARE_NAME: RepRapFirmware');
    expect(codes).toEqual(['M115']);
    expect(asks.at(-1)).toBe('after=3&ticket=t-1');
    expect(logged).toEqual([]);
    // A message of the board: the number moves, the feed gives it, once.
    messages.push({ id: 4, text: 'Driver 0.3 warning' });
    head = 4;
    parts['seqs'] = { reply: 7 };
    await c.rrf.poll();
    await c.rrf.poll();
    expect(logged).toEqual(['Driver 0.3 warning']);
    expect(asks.every((a) => !a.includes('seq='))).toBe(true);
  });

  it('rr_connect err 2 through the gateway (503 {"err":2}) reads as "no free session"; err 1 as 403', async () => {
    server.use(http.get(`${base}/machine/connect`, () => HttpResponse.json({ err: 2 }, { status: 503 })));
    const c = new DuetClient('rc');
    await expect(c.connect()).rejects.toThrow(/no free session/);
    server.use(http.get(`${base}/machine/connect`, () => HttpResponse.json({ err: 1 }, { status: 403 })));
    await expect(c.connect()).rejects.toMatchObject({ status: 403 });
    // DSF's connect answer has no err: DSF.
    server.use(http.get(`${base}/machine/connect`, () => HttpResponse.json({ sessionKey: null })));
    await c.connect();
    expect(c.api).toBe('dsf');
  });

  it('a failed file operation ({"err":1}) throws; a listing follows next', async () => {
    const pages: Record<string, Record<string, unknown>> = {
      '0': {
        dir: '0:/gcodes',
        first: 0,
        files: [{ type: 'f', name: 'a.g', size: 1, date: '2024-01-01T00:00:00' }],
        next: 1,
      },
      '1': {
        dir: '0:/gcodes',
        first: 1,
        files: [{ type: 'd', name: 'sub', date: '2024-01-01T00:00:00' }, 'junk'],
        next: 0,
      },
    };
    board({ state: {}, seqs: {} });
    server.use(
      http.get(`${base}/rr_filelist`, ({ request }) =>
        HttpResponse.json(pages[new URL(request.url).searchParams.get('first') ?? '0']),
      ),
      http.get(`${base}/rr_delete`, () => HttpResponse.json({ err: 1 })),
    );
    const c = await connected();
    expect((await c.listDirectory('0:/gcodes')).map((e) => e.name)).toEqual(['a.g', 'sub']);
    await expect(c.deleteFile('0:/gcodes/a.g')).rejects.toThrow(/err 1/);
  });
});
