import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import { createLogger } from './log';
import { shownUrl, Webhook, webhookUrlProblem } from './webhook';

/** A real receiver on localhost: answers each POST with the next status of `statuses`. */
async function receiver(statuses: number[], opts: { slowBody?: boolean } = {}) {
  const got: Array<{ body: unknown; type: string | undefined }> = [];
  const server = http.createServer((req, res) => {
    let text = '';
    req.on('data', (c: Buffer) => (text += c.toString()));
    req.on('end', () => {
      got.push({ body: JSON.parse(text) as unknown, type: req.headers['content-type'] });
      const status = statuses.shift() ?? 200;
      if (status === 302) {
        res.writeHead(302, { Location: 'http://127.0.0.1:1/elsewhere' });
        res.end();
      } else if (opts.slowBody) {
        // An endless answer: the webhook must not wait for it.
        res.writeHead(status, { 'Content-Type': 'text/plain' });
        res.write('x'.repeat(1000));
      } else {
        res.writeHead(status);
        res.end('<html>ok</html>');
      }
    });
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  const url = `http://127.0.0.1:${(server.address() as AddressInfo).port}/hooks/T0KEN?secret=s3`;
  return {
    url,
    got,
    close: () =>
      new Promise<void>((r) => {
        server.closeAllConnections();
        server.close(() => r());
      }),
  };
}

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function until(what: string, ok: () => boolean, ms = 5000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 10));
  }
}

function hook(url: string | null, backoffMs = [20, 20, 20]) {
  const lines: string[] = [];
  const w = new Webhook({
    url: () => url,
    log: createLogger({ write: (l) => lines.push(l) }),
    backoffMs,
    timeoutMs: 2000,
    // The receivers of these tests are on this computer: allowed as the settings file would.
    allowedHosts: () => ['127.0.0.1'],
  });
  cleanups.push(() => w.close());
  return { w, lines };
}

describe('the alarm webhook', () => {
  it('posts each event as JSON, in order', async () => {
    const r = await receiver([]);
    cleanups.push(r.close);
    const { w } = hook(r.url);
    w.send('a', { event: 'alarm.raised', n: 1 });
    w.send('b', { event: 'alarm.cleared', n: 2 });
    await until('two deliveries', () => w.stats.delivered === 2);
    expect(r.got.map((g) => g.body)).toEqual([
      { event: 'alarm.raised', n: 1 },
      { event: 'alarm.cleared', n: 2 },
    ]);
    expect(r.got[0]?.type).toBe('application/json');
  });

  it('retries with backoff while the receiver is down (5xx), then delivers', async () => {
    const r = await receiver([503, 500]);
    cleanups.push(r.close);
    const { w, lines } = hook(r.url);
    w.send('a', { n: 1 });
    await until('delivered', () => w.stats.delivered === 1);
    expect(r.got).toHaveLength(3);
    expect(lines.join('\n')).toMatch(/answered 503; trying again/);
    // The log never shows the secret part of the URL.
    expect(lines.join('\n')).not.toMatch(/T0KEN|s3/);
  });

  it('retries when nothing answers, and gives up after the last try with an error line', async () => {
    const { w, lines } = hook('http://127.0.0.1:1/hook', [10, 10]);
    w.send('alarm.raised 7', { n: 1 });
    await until('given up', () => w.stats.failed === 1);
    expect(lines.filter((l) => /trying again/.test(l))).toHaveLength(2);
    expect(lines.join('\n')).toMatch(/alarm\.raised 7 not delivered .* after 3 tries/);
  });

  it('a receiver that refuses (4xx) is not retried; a redirect is not followed', async () => {
    const r = await receiver([404, 302]);
    cleanups.push(r.close);
    const { w } = hook(r.url);
    w.send('a', { n: 1 });
    w.send('b', { n: 2 });
    await until('both done', () => w.stats.failed === 2);
    expect(r.got).toHaveLength(2);
  });

  it('does not wait for an endless answer body', async () => {
    const r = await receiver([200], { slowBody: true });
    cleanups.push(r.close);
    const { w } = hook(r.url);
    w.send('a', { n: 1 });
    await until('delivered', () => w.stats.delivered === 1, 1500);
  });

  it('a bounded queue: the oldest waiting event goes when it overflows; nothing queued without a URL', async () => {
    const none = hook(null);
    none.w.send('a', { n: 1 });
    expect(none.w.waiting).toBe(0);
    const lines: string[] = [];
    const w = new Webhook({
      url: () => 'http://127.0.0.1:1/x',
      log: createLogger({ write: (l) => lines.push(l) }),
      allowedHosts: () => ['127.0.0.1'],
      backoffMs: [60_000],
      maxQueue: 2,
    });
    cleanups.push(() => w.close());
    for (let i = 0; i < 4; i++) w.send(`e${i}`, { n: i });
    expect(w.waiting).toBe(2);
    expect(w.stats.dropped).toBe(2);
  });

  it('accepts only http(s) URLs without credentials, and shows only where they point', () => {
    expect(webhookUrlProblem('https://hooks.example.com/services/T0/B1/XYZ')).toBeNull();
    expect(webhookUrlProblem('file:///etc/passwd')).toMatch(/https/);
    expect(webhookUrlProblem('javascript:alert(1)')).toMatch(/https/);
    expect(webhookUrlProblem('https://user:pw@example.com/')).toMatch(/password/);
    expect(webhookUrlProblem('not a url')).toMatch(/not a URL/);
    expect(shownUrl('https://hooks.example.com/services/T0/B1/XYZ?k=1')).toBe('https://hooks.example.com/…');
    expect(shownUrl('http://10.0.0.5:8080/')).toBe('http://10.0.0.5:8080/');
  });
});

describe('where the webhook may connect (finding 14)', () => {
  /** A webhook with its own name resolution: `names` answers, `asked` counts the questions. */
  function resolving(
    names: Record<string, string[]>,
    opts: { allowed?: string[]; machines?: string[] } = {},
  ) {
    const asked: string[] = [];
    const lines: string[] = [];
    let url = '';
    const w = new Webhook({
      url: () => url,
      log: createLogger({ write: (l) => lines.push(l) }),
      timeoutMs: 300,
      allowedHosts: () => opts.allowed ?? [],
      machineHosts: () => opts.machines ?? [],
      resolve: (host) => {
        asked.push(host);
        const list = names[host];
        if (!list) return Promise.reject(new Error('ENOTFOUND'));
        return Promise.resolve(list.map((address) => ({ address, family: address.includes(':') ? 6 : 4 })));
      },
    });
    cleanups.push(() => w.close());
    return {
      w,
      asked,
      lines,
      test: (u: string) => {
        url = u;
        return w.tryOnce({ event: 'test' });
      },
    };
  }

  it('refuses a name resolving to loopback, link-local, or a machine’s address, before connecting', async () => {
    const h = resolving(
      {
        'hook.rebind.test': ['203.0.113.7', '127.0.0.1'],
        'metadata.test': ['169.254.169.254'],
        'v6.test': ['::ffff:127.0.0.1'],
        'laser.shop.test': ['192.0.2.10'],
        'alias.shop.test': ['192.0.2.10'],
      },
      { machines: ['laser.shop.test', '192.0.2.20'] },
    );
    for (const u of [
      'http://hook.rebind.test/x',
      'http://metadata.test/latest',
      'http://v6.test/',
      'http://laser.shop.test:8080/cnc/data?action=stop',
      'http://alias.shop.test/',
      'http://192.0.2.20/machine/code',
      'http://[::ffff:192.0.2.20]/',
    ]) {
      const r = await h.test(u);
      expect(r.ok, u).toBe(false);
      expect(r.error, u).toMatch(/^refused: /);
    }
    // Nothing was delivered anywhere, and each refusal is in the server's log with its reason.
    expect(h.lines.filter((l) => /test was not delivered .*refused/.test(l))).toHaveLength(7);
  });

  it('connects to the address it checked: the name is resolved once, never again by the system', async () => {
    // 192.0.2.1 (TEST-NET-1) is routed nowhere: the connection fails or times out, but it is not
    // a failure to resolve `hook.pinned.test` (which the system's resolver could not).
    const h = resolving({ 'hook.pinned.test': ['192.0.2.1'] });
    const r = await h.test('http://hook.pinned.test/hook');
    expect(r.ok).toBe(false);
    expect(r.error).not.toMatch(/refused|ENOTFOUND|EAI_AGAIN|resolved/);
    expect(h.asked).toEqual(['hook.pinned.test']);
  });

  it('an explicitly allowed host is reached, by host or by host:port only', async () => {
    const r = await receiver([204]);
    cleanups.push(r.close);
    const port = new URL(r.url).port;
    const byPort = resolving({}, { allowed: [`127.0.0.1:${port}`] });
    expect(await byPort.test(r.url)).toMatchObject({ ok: true, status: 204 });
    expect((await byPort.test(`http://127.0.0.1:${Number(port) === 1 ? 2 : 1}/x`)).error).toMatch(/^refused/);
    const wrong = resolving({}, { allowed: ['127.0.0.2'] });
    expect((await wrong.test(r.url)).error).toMatch(/^refused/);
    expect(r.got).toHaveLength(1);
  });
});
