import { http, HttpResponse, delay } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it, vi } from 'vitest';
import { z } from 'zod/mini';
import { describeError, LinkError } from './errors';
import { controlledBody, installFakeFetch } from './fake-fetch.test-util';
import { connectionLost, HttpClient, signInWords } from './http';

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => server.resetHandlers());
afterAll(() => server.close());

const base = 'http://shopdeck.test/machines/m1';
const Progress = z.object({ progress: z.coerce.number(), working: z.coerce.number() });

async function caught(p: Promise<unknown>): Promise<LinkError> {
  try {
    await p;
  } catch (e) {
    if (e instanceof LinkError) return e;
    throw e;
  }
  throw new Error('expected a LinkError');
}

describe('HttpClient error taxonomy', () => {
  it('parses JSON sent without a JSON content type and coerces sloppy numbers', async () => {
    server.use(
      http.get(
        `${base}/progress`,
        () =>
          new HttpResponse('{"progress":"12.5","working":"300"}', {
            headers: { 'Content-Type': 'text/html' },
          }),
      ),
    );
    const c = new HttpClient({ machineId: 'm1' });
    await expect(c.json({ path: '/progress' }, Progress)).resolves.toEqual({ progress: 12.5, working: 300 });
  });

  it('classifies a network failure', async () => {
    server.use(http.get(`${base}/progress`, () => HttpResponse.error()));
    const e = await caught(new HttpClient({ machineId: 'm1' }).json({ path: '/progress' }, Progress));
    expect(e.kind).toBe('network');
  });

  it('classifies a timeout', async () => {
    server.use(
      http.get(`${base}/progress`, async () => {
        await delay(500);
        return HttpResponse.json({});
      }),
    );
    const e = await caught(
      new HttpClient({ machineId: 'm1', timeoutMs: 50 }).json({ path: '/progress' }, Progress),
    );
    expect(e.kind).toBe('timeout');
  });

  it('carries the HTTP status, and the vendor code and message when the family parses them', async () => {
    server.use(
      http.get(`${base}/status`, () =>
        HttpResponse.json({ code: '1003', msg: 'Missing parameter' }, { status: 400 }),
      ),
    );
    const plain = await caught(new HttpClient({ machineId: 'm1' }).raw({ path: '/status' }));
    expect(plain.kind).toBe('http');
    expect(plain.status).toBe(400);
    const withVendor = new HttpClient({
      machineId: 'm1',
      parseError: (status, body) => {
        const r = z.object({ code: z.string(), msg: z.string() }).safeParse(body);
        return r.success
          ? new LinkError('vendor', r.data.msg, {
              status,
              vendorCode: r.data.code,
              vendorMessage: r.data.msg,
            })
          : null;
      },
    });
    const v = await caught(withVendor.raw({ path: '/status' }));
    expect(v.kind).toBe('vendor');
    expect(v.vendorCode).toBe('1003');
    expect(v.status).toBe(400);
  });

  it('turns a payload that fails validation into a protocol error naming the path', async () => {
    server.use(http.get(`${base}/progress`, () => HttpResponse.json({ progress: 'lots', working: 1 })));
    const e = await caught(new HttpClient({ machineId: 'm1' }).json({ path: '/progress' }, Progress));
    expect(e.kind).toBe('protocol');
    expect(e.path).toBe('progress');
    expect(e.message).toContain('/progress');
  });

  it('reports a body that is not JSON as a protocol error', async () => {
    server.use(http.get(`${base}/progress`, () => new HttpResponse('{"progress":1,')));
    const e = await caught(new HttpClient({ machineId: 'm1' }).json({ path: '/progress' }, Progress));
    expect(e.kind).toBe('protocol');
  });

  it('serializes requests when asked: never two at once to a fragile controller', async () => {
    let concurrent = 0;
    let max = 0;
    server.use(
      http.get(`${base}/ping`, async () => {
        concurrent++;
        max = Math.max(max, concurrent);
        await delay(20);
        concurrent--;
        return HttpResponse.json({ result: 'ok' });
      }),
    );
    const c = new HttpClient({ machineId: 'm1', serial: true });
    await Promise.all([1, 2, 3, 4].map(() => c.raw({ path: '/ping' })));
    expect(max).toBe(1);
    const free = new HttpClient({ machineId: 'm1' });
    max = 0;
    await Promise.all([1, 2, 3, 4].map(() => free.raw({ path: '/ping' })));
    expect(max).toBeGreaterThan(1);
  });

  it('sends the command id for the audit log', async () => {
    let seen: string | null = null;
    server.use(
      http.get(`${base}/cnc/data`, ({ request }) => {
        seen = request.headers.get('X-Shopdeck-Command');
        return HttpResponse.json({ result: 'ok' });
      }),
    );
    await new HttpClient({ machineId: 'm1' }).raw({
      path: '/cnc/data',
      query: { action: 'pause' },
      commandId: 'xtool.pause',
    });
    expect(seen).toBe('xtool.pause');
  });
});

describe('HttpClient.blob', () => {
  it('throws on an error status instead of returning the error page as an image', async () => {
    server.use(http.get(`${base}/screenshot`, () => new HttpResponse('busy', { status: 503 })));
    const e = await caught(new HttpClient({ machineId: 'm1' }).blob({ path: '/screenshot' }));
    expect(e.kind).toBe('http');
    expect(e.status).toBe(503);
  });
});

describe('answers of the console server itself', () => {
  it('are never read as the controller’s: words, kind by status, marked as the gateway’s', async () => {
    const { gatewayError } = await import('./http');
    const down = new Response(JSON.stringify({ error: 'Laser refused the connection' }), {
      status: 502,
      headers: { 'X-Shopdeck-Gateway': 'error' },
    });
    const e = gatewayError(down, { error: 'Laser refused the connection' });
    expect(e?.kind).toBe('network');
    expect(e?.message).toBe('Laser refused the connection');
    expect(e?.gateway).toBe(true);
    const refused = new Response('{}', { status: 403, headers: { 'X-Shopdeck-Gateway': 'error' } });
    expect(gatewayError(refused, {})?.kind).toBe('http');
    // The controller's own 502 (no mark) is left to the family's error parser.
    expect(gatewayError(new Response('{}', { status: 502 }), {})).toBeNull();
  });
});

describe('the whole answer (issue 15)', () => {
  afterEach(() => {
    vi.useRealTimers();
    vi.unstubAllGlobals();
  });

  /** A promise's state without waiting for it. */
  function watch<T>(p: Promise<T>): { settled: () => boolean; result: () => Promise<T> } {
    let settled = false;
    p.then(
      () => (settled = true),
      () => (settled = true),
    );
    return { settled: () => settled, result: () => p };
  }

  it('its timeout covers the body: headers and 20 bytes, then silence, is a timeout', async () => {
    vi.useFakeTimers();
    const f = installFakeFetch();
    const c = new HttpClient({ machineId: 'm1', timeoutMs: 1000 });
    const p = watch(caught(c.json({ path: '/progress' }, Progress)));
    await vi.advanceTimersByTimeAsync(0);
    const body = controlledBody();
    f.last().answer(200, body, { 'Content-Type': 'application/json' });
    body.push('{"progress":12.5,"w');
    await vi.advanceTimersByTimeAsync(999);
    expect(p.settled()).toBe(false);
    await vi.advanceTimersByTimeAsync(2);
    expect(p.settled()).toBe(true);
    const e = await p.result();
    expect(e.kind).toBe('timeout');
    expect(e.message).toContain('/progress');
    expect(f.last().signal.aborted).toBe(true);
  });

  it('a body cut partway is a network error (a link problem), never a protocol error', async () => {
    vi.useFakeTimers();
    const f = installFakeFetch();
    const c = new HttpClient({ machineId: 'm1' });
    const p = caught(c.json({ path: '/status_report' }, Progress));
    await vi.advanceTimersByTimeAsync(0);
    const body = controlledBody();
    f.last().answer(200, body);
    body.push('{"progress":12.5,"w');
    body.cut();
    const e = await p;
    expect(e.kind).toBe('network');
    expect(e.isLinkFailure).toBe(true);
    expect(e.message).toMatch(/cut/);
  });

  it('the same for a binary answer (blob)', async () => {
    vi.useFakeTimers();
    const f = installFakeFetch();
    const c = new HttpClient({ machineId: 'm1', timeoutMs: 1000 });
    const p = watch(caught(c.blob({ path: '/screenshot' })));
    await vi.advanceTimersByTimeAsync(0);
    const body = controlledBody();
    f.last().answer(200, body, { 'Content-Type': 'image/png' });
    body.push('PNG-partial');
    await vi.advanceTimersByTimeAsync(1001);
    expect(p.settled()).toBe(true);
    expect((await p.result()).kind).toBe('timeout');
  });
});

describe('the gateway’s own failures (issue 15)', () => {
  afterEach(() => {
    vi.unstubAllGlobals();
  });

  /** A family parser that reads every 502 as its own verdict (what the Duet session once did). */
  const verdict = (status: number): LinkError | null =>
    status === 502 ? new LinkError('vendor', 'Incompatible DCS version (502)', { status }) : null;

  it('are told apart by the header: the gateway’s words, a link failure, never the vendor’s verdict', async () => {
    const f = installFakeFetch();
    f.auto = (call) => {
      call.answer(502, JSON.stringify({ error: 'Laser 1 cannot be reached on the network', gateway: true }), {
        'X-Shopdeck-Gateway': 'error',
        'Content-Type': 'application/json',
      });
      return true;
    };
    const c = new HttpClient({ machineId: 'm1', parseError: verdict });
    const e = await caught(c.json({ path: '/machine/status' }, Progress));
    expect(e.kind).toBe('network');
    expect(e.fromGateway).toBe(true);
    expect(e.isLinkFailure).toBe(true);
    expect(e.message).toBe('Laser 1 cannot be reached on the network');
    expect(describeError(e)).toBe('Laser 1 cannot be reached on the network');
  });

  it('are told apart by the body too (gateway: true on a 5xx), and a 504 "not confirmed" says so', async () => {
    const f = installFakeFetch();
    f.auto = (call) => {
      call.answer(
        504,
        JSON.stringify({
          error: 'Printer 1 did not confirm pause within 5 s: it may or may not have reached the machine',
          gateway: true,
          notConfirmed: true,
        }),
      );
      return true;
    };
    const c = new HttpClient({ machineId: 'm1', parseError: verdict });
    const e = await caught(c.raw({ method: 'POST', path: '/pause' }));
    expect(e.kind).toBe('timeout');
    expect(e.fromGateway).toBe(true);
    expect(e.notConfirmed).toBe(true);
    expect(e.message).toMatch(/^Printer 1 did not confirm pause within 5 s/);
  });

  it('a controller’s own 502 is still the family’s to read; a controller’s JSON error reads as words', async () => {
    const f = installFakeFetch();
    f.auto = (call) => {
      if (call.url.endsWith('/a')) call.answer(502, '{"err":1}');
      else call.answer(500, JSON.stringify({ error: 'motion controller busy', code: 7 }));
      return true;
    };
    const c = new HttpClient({ machineId: 'm1', parseError: verdict });
    const a = await caught(c.raw({ path: '/a' }));
    expect(a.kind).toBe('vendor');
    expect(a.fromGateway).toBe(false);
    const b = await caught(c.raw({ path: '/b' }));
    expect(b.kind).toBe('http');
    expect(b.message).toBe('HTTP 500 from /b: motion controller busy');
    expect(b.message).not.toContain('{');
  });

  it('describeError never shows a JSON dump', () => {
    expect(describeError(new Error('{"error":"cannot reach the controller of acc-laser"}'))).toBe(
      'cannot reach the controller of acc-laser',
    );
    expect(describeError(new Error('plain words'))).toBe('plain words');
  });
});

describe('words that reach people', () => {
  it('leaves out the browser\'s own "Failed to fetch" (and its kin), keeps another reason', () => {
    for (const why of ['Failed to fetch', 'NetworkError when attempting to fetch resource.', 'Load failed'])
      expect(connectionLost(why)).toBe('No answer: the connection to the console server broke');
    expect(connectionLost('socket hang up')).toBe(
      'No answer: the connection to the console server broke (socket hang up)',
    );
  });

  it('says "sign in" as the sign-in screen does, never the server\'s "log in first"', async () => {
    expect(signInWords('log in first')).toBe('You are not signed in: sign in to see this machine.');
    expect(signInWords('your session expired: log in again')).toMatch(/^Your sign-in has expired/);
    server.use(
      http.get(`${base}/progress`, () =>
        HttpResponse.json(
          { error: 'log in first', needs: 'viewer', login: true },
          { status: 401, headers: { 'X-Shopdeck-Gateway': 'error' } },
        ),
      ),
    );
    const e = await caught(new HttpClient({ machineId: 'm1' }).json({ path: '/progress' }, Progress));
    expect(e.message).toBe('You are not signed in: sign in to see this machine.');
  });
});
