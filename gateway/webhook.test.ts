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
