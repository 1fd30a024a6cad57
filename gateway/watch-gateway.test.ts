import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { xtoolFamily } from '../src/controllers/xtool/family';
import type { FamilyDescriptor } from '../src/fleet/contract';
import type { Simulator, SimControl } from '../src/fleet/sim';
import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { AlarmCentre } from './alarms';
import { createLogger, type Logger } from './log';
import { consoleFetch, login, startGateway, tempDir, user, writeJson } from './test-util';

/**
 * The gateway watches a machine nobody looks at (watch.ts through the real gateway): a simulated
 * xTool with no browser open; its job start and a flame reach the audit log.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function until(what: string, ok: () => boolean | Promise<boolean>, ms = 8000): Promise<void> {
  const end = Date.now() + ms;
  while (!(await ok())) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 20));
  }
}

describe('the gateway’s watch, with no viewer', () => {
  it('holds the shared stream, polls, and writes job starts and alarms to the audit log', async () => {
    let sim: Simulator | null = null;
    const sharing = xtoolFamily.gateway?.sharing;
    const watch = sharing?.watch;
    if (!sharing || !watch) throw new Error('the xTool family declares no watch');
    const family: FamilyDescriptor = {
      ...xtoolFamily,
      gateway: { ...xtoolFamily.gateway, sharing: { ...sharing, watch: { ...watch, everyMs: 150 } } },
      createSimulator: (o) => (sim = xtoolFamily.createSimulator(o)),
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 'x1', name: 'Laser', kind: 'xtool', simulated: true, url: null, wsUrl: null, secrets: {} },
        ],
      },
      families: { xtool: family },
      dataDir: t.dir,
      env: {},
      watch: true,
    });
    cleanups.push(gw.close);
    await until('the watch holds the laser’s socket', () => gw.gw.streamStats('x1').open === 1);
    const auditLines = async (): Promise<Array<{ type: string; label?: string; detail?: string }>> => {
      await gw.gw.audit.flush();
      return gw.gw.audit.all();
    };
    const control = (id: string): SimControl => {
      const s: Simulator | null = sim;
      const c = s?.controls?.().find((x) => x.id === id);
      if (!c) throw new Error(`no control ${id}`);
      return c;
    };
    const run = (id: string): void => control(id).run();
    run('demo');
    let seen: Array<{ type: string; label?: string; detail?: string }> = [];
    await until('job started in the audit log', async () => {
      seen = await auditLines();
      return seen.some((e) => e.type === 'machine' && e.label === 'job started');
    });
    run('flame');
    await until('the flame in the audit log', async () => {
      seen = await auditLines();
      return seen.some((e) => e.type === 'machine' && e.label === 'alarm');
    });
    expect(seen.find((e) => e.label === 'alarm')?.detail).toMatch(/flame/i);
    // Nobody opened a browser socket: the one upstream socket is the watch's.
    expect(gw.gw.streamStats('x1').joined).toBe(0);
  });
});

/** A webhook receiver on localhost that records what it is sent. */
async function receiver(): Promise<{ url: string; got: unknown[]; close(): Promise<void> }> {
  const got: unknown[] = [];
  const server = http.createServer((req, res) => {
    let text = '';
    req.on('data', (c: Buffer) => (text += c.toString()));
    req.on('end', () => {
      got.push(JSON.parse(text));
      res.writeHead(204);
      res.end();
    });
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  return {
    url: `http://127.0.0.1:${(server.address() as AddressInfo).port}/hook/secret-token`,
    got,
    close: () =>
      new Promise<void>((r) => {
        server.closeAllConnections();
        server.close(() => r());
      }),
  };
}

describe('the alarm centre, with no page open', () => {
  /** `everyMs`: the watch's poll period (150 ms unless a test needs a reading to stand still). */
  async function setup(o: { log?: Logger; dir?: string; everyMs?: number } = {}) {
    const sims = new Map<string, Simulator>();
    const sharing = xtoolFamily.gateway?.sharing;
    const watch = sharing?.watch;
    if (!sharing || !watch) throw new Error('the xTool family declares no watch');
    const family: FamilyDescriptor = {
      ...xtoolFamily,
      gateway: {
        ...xtoolFamily.gateway,
        sharing: { ...sharing, watch: { ...watch, everyMs: o.everyMs ?? 150 } },
      },
      createSimulator: (o) => {
        const sim = xtoolFamily.createSimulator(o);
        sims.set(o.id, sim);
        return sim;
      },
    };
    const t = o.dir ? { dir: o.dir, cleanup: () => undefined } : tempDir();
    cleanups.push(t.cleanup);
    const hook = await receiver();
    cleanups.push(hook.close);
    // The receiver is on this computer: allowed by the server's settings file, as it must be.
    writeJson(path.join(t.dir, 'settings.json'), { webhookAllowHosts: ['127.0.0.1'] });
    const usersFile = path.join(t.dir, 'users.json');
    writeJson(usersFile, {
      users: [
        user('vera', 'viewer', 'vera-pass-1'),
        user('otto', 'operator', 'otto-pass-1'),
        user('sam', 'supervisor', 'sam-pass-1'),
        user('lena', 'operator', 'lena-pass-1', { machines: ['other'] }),
      ],
    });
    const entry = {
      name: 'Laser',
      kind: 'xtool' as const,
      simulated: true,
      url: null,
      wsUrl: null,
      secrets: {},
    };
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 'x1', ...entry },
          { id: 'other', ...entry, name: 'Other' },
        ],
      },
      families: { xtool: family },
      dataDir: t.dir,
      usersFile,
      env: { SHOPDECK_ALARM_WEBHOOK: hook.url },
      watch: true,
      ...(o.log ? { log: o.log } : {}),
    });
    cleanups.push(gw.close);
    await until('the watch holds the laser’s socket', () => gw.gw.streamStats('x1').open === 1);
    const flame = (): void => {
      const c = sims
        .get('x1')
        ?.controls?.()
        .find((x) => x.id === 'flame');
      if (!c) throw new Error('no flame control');
      c.run();
    };
    return { gw, hook, flame, dir: t.dir };
  }

  interface Listed {
    version: number;
    alarms: Array<{ id: string; key: string; severity: string; ackBy: string | null; machine: string }>;
  }
  const list = async (base: string, cookie: string, query = ''): Promise<Listed> => {
    const r = await consoleFetch(`${base}/api/alarms${query}`, { headers: { cookie } });
    expect(r.status).toBe(200);
    return (await r.json()) as Listed;
  };
  const ack = (base: string, cookie: string, body: unknown, headers: Record<string, string> = {}) =>
    consoleFetch(`${base}/api/alarms/ack`, {
      method: 'POST',
      headers: { cookie, 'Content-Type': 'application/json', ...headers },
      body: JSON.stringify(body),
    });

  it('a flame is in the list and sent to the webhook; an operator acknowledges it, recorded', async () => {
    const { gw, hook, flame } = await setup();
    const vera = await login(gw.url, 'vera', 'vera-pass-1');
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    flame();
    let listed: Listed = { version: 0, alarms: [] };
    await until('the flame in the alarm list', async () => {
      listed = await list(gw.url, vera);
      return listed.alarms.some((a) => a.key === 'xtool-flame');
    });
    const rec = listed.alarms.find((a) => a.key === 'xtool-flame');
    expect(rec).toMatchObject({ machine: 'x1', severity: 'critical', ackBy: null });
    // Nothing new: the page is told so, not sent the list again (the watch may change it between
    // the two requests: then the answer is the new list).
    await until('an unchanged answer', async () => {
      const v = (await list(gw.url, vera)).version;
      const same = await consoleFetch(`${gw.url}/api/alarms?since=${v}`, { headers: { cookie: vera } });
      const body = (await same.json()) as { version: number; unchanged?: boolean; alarms?: unknown[] };
      if (body.version !== v) return false;
      expect(body).toEqual({ version: v, unchanged: true });
      return true;
    });
    await until('the webhook received it', () => hook.got.length > 0);
    expect(hook.got[0]).toMatchObject({
      source: 'shopdeck',
      event: 'alarm.raised',
      alarm: { machine: 'x1', key: 'xtool-flame', severity: 'critical' },
    });
    expect(String((hook.got[0] as { text: string }).text)).toMatch(/^Alarm: Laser: critical — FLAME/);

    // A viewer may see it, not acknowledge it: refused and recorded.
    const refused = await ack(gw.url, vera, { id: rec?.id });
    expect(refused.status).toBe(403);
    const ok = await ack(gw.url, otto, { id: rec?.id });
    expect(ok.status).toBe(200);
    const after = await list(gw.url, vera);
    expect(after.alarms.find((a) => a.id === rec?.id)?.ackBy).toBe('otto');
    await gw.gw.audit.flush();
    const audit = gw.gw.audit.all();
    expect(audit.find((e) => e.type === 'alarm-ack')).toMatchObject({ user: 'otto', machine: 'x1' });
    expect(audit.find((e) => e.type === 'refused' && e.label === 'acknowledge alarm')).toMatchObject({
      user: 'vera',
    });
    await until('the acknowledgement sent on', () =>
      hook.got.some((g) => (g as { event: string }).event === 'alarm.acknowledged'),
    );
  });

  it('the machines list carries the watch reading of the user machines only (the first screen)', async () => {
    // The laser's reading of the flame stands until the watch's next poll (the D-series is idle
    // again at once, and its poll says so): a slow poll here, so that a busy machine cannot let
    // the reading pass between two looks at the list.
    const { gw, flame } = await setup({ everyMs: 60_000 });
    const vera = await login(gw.url, 'vera', 'vera-pass-1');
    const lena = await login(gw.url, 'lena', 'lena-pass-1');
    type Listed = {
      machines: Array<{
        id: string;
        watch?: { state: string; alarm: string | null; alarmSeverity: string | null; ageMs: number | null };
      }>;
    };
    const machines = async (cookie: string): Promise<Listed['machines']> => {
      const r = await consoleFetch(`${gw.url}/api/machines`, { headers: { cookie } });
      expect(r.status).toBe(200);
      return ((await r.json()) as Listed).machines;
    };
    // The watch's first poll (within 2 s of its start) has read the laser: the flame comes after it.
    await until('the laser read by the watch', async () =>
      (await machines(vera)).some((m) => m.id === 'x1' && m.watch?.state === 'idle'),
    );
    flame();
    let seen: Listed['machines'] = [];
    await until('the flame in the machines list', async () => {
      seen = await machines(vera);
      return seen.find((m) => m.id === 'x1')?.watch?.alarm != null;
    });
    const x1 = seen.find((m) => m.id === 'x1')?.watch;
    expect(x1?.state).toBe('alarm');
    expect(x1?.alarmSeverity).toBe('critical');
    expect(typeof x1?.ageMs).toBe('number');
    // Lena may use "other" only: the laser is not in her list at all, nor its reading.
    const hers = await machines(lena);
    expect(hers.map((m) => m.id)).toEqual(['other']);
    expect(JSON.stringify(hers)).not.toContain('flame');
    // No login: no list (and no reading).
    const anon = await consoleFetch(`${gw.url}/api/machines`);
    expect(anon.status).toBe(401);
    // Another site's page with Vera's cookie (a fetch, a frame): refused, nothing of the reading.
    const forged: Array<Record<string, string>> = [
      { cookie: vera, 'Sec-Fetch-Site': 'cross-site' },
      { cookie: vera, 'Sec-Fetch-Site': 'same-site' },
      { cookie: vera, Origin: 'http://evil.example' },
    ];
    for (const headers of forged) {
      const r = await fetch(`${gw.url}/api/machines`, { headers });
      expect(r.status).toBe(403);
      expect(await r.text()).not.toMatch(/flame|"watch"/i);
    }
  });

  it('refuses a forged acknowledgement: another site, no login, a machine the user may not use', async () => {
    const { gw, flame } = await setup();
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const lena = await login(gw.url, 'lena', 'lena-pass-1');
    flame();
    let id = '';
    await until('the flame in the alarm list', async () => {
      id = (await list(gw.url, otto)).alarms[0]?.id ?? '';
      return id !== '';
    });
    // Another web site's form or fetch with the operator's cookie.
    const cross = await fetch(`${gw.url}/api/alarms/ack`, {
      method: 'POST',
      headers: { cookie: otto, 'Content-Type': 'text/plain', Origin: 'https://evil.example' },
      body: JSON.stringify({ id }),
    });
    expect(cross.status).toBe(403);
    expect((await ack(gw.url, '', { id })).status).toBe(401);
    // An operator of another machine sees nothing of this one and cannot acknowledge it.
    expect((await list(gw.url, lena)).alarms.filter((a) => a.machine === 'x1')).toEqual([]);
    expect((await ack(gw.url, lena, { id })).status).toBe(404);
    expect((await ack(gw.url, lena, { machine: 'x1', key: 'xtool-flame' })).status).toBe(404);
    expect((await ack(gw.url, otto, { id, extra: 1 })).status).toBe(400);
    const still = (await list(gw.url, otto)).alarms.find((a) => a.id === id);
    expect(still?.ackBy).toBeNull();
  });

  it('an alarm cannot be acknowledged before it happens, nor by an invented key (finding 3)', async () => {
    const { gw, flame } = await setup();
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const vera = await login(gw.url, 'vera', 'vera-pass-1');
    // The pen test's attack: the flame's real key, before any flame, then invented keys.
    const early = await ack(gw.url, otto, { machine: 'x1', key: 'xtool-flame' });
    expect(early.status).toBe(404);
    expect(await early.json()).not.toHaveProperty('early');
    for (let i = 0; i < 50; i++)
      expect((await ack(gw.url, otto, { machine: 'x1', key: `invented-${i}` })).status).toBe(404);
    expect(gw.gw.audit.all().filter((e) => e.type === 'alarm-ack')).toEqual([]);
    // The flame that follows at once is unacknowledged, in every list (another person's screen,
    // one opened afterwards).
    flame();
    let listed: Listed = { version: 0, alarms: [] };
    await until('the flame in the alarm list', async () => {
      listed = await list(gw.url, vera, '?state=unacknowledged');
      return listed.alarms.some((a) => a.key === 'xtool-flame');
    });
    expect(listed.alarms.find((a) => a.key === 'xtool-flame')).toMatchObject({ machine: 'x1', ackBy: null });
    const later = await login(gw.url, 'vera', 'vera-pass-1');
    const fresh = await list(gw.url, later);
    expect(fresh.alarms.find((a) => a.key === 'xtool-flame')?.ackBy).toBeNull();
    // Now that the record exists, it can be acknowledged (by its id, as the page does).
    const id = listed.alarms.find((a) => a.key === 'xtool-flame')?.id;
    const ok = await ack(gw.url, otto, { id });
    expect(ok.status).toBe(200);
    expect((await list(gw.url, vera)).alarms.find((a) => a.key === 'xtool-flame')?.ackBy).toBe('otto');
  });

  it('the flame is on disk before the log, the audit log or the webhook hear of it (finding 15)', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const silent = createLogger({ write: () => undefined });
    /** What a restart would find at this moment: the alarm centre read again from the folder. */
    const onDiskNow = (): string[] =>
      new AlarmCentre({ dataDir: t.dir, log: silent }).query({ machines: null }).map((r) => r.key);
    const whenLogged: string[][] = [];
    const log = createLogger({
      write: (line) => {
        if (/x1: alarm \(/.test(line)) whenLogged.push(onDiskNow());
      },
    });
    const { hook, flame } = await setup({ log, dir: t.dir });
    // (The watch's audit entry is written in the same step as its log line, right after it.)
    const whenHooked: string[][] = [];
    const got = hook.got.length;
    flame();
    await until('the webhook received the flame', () => {
      if (hook.got.length > got && whenHooked.length === 0) whenHooked.push(onDiskNow());
      return whenHooked.length > 0;
    });
    await until('the log line', () => whenLogged.length > 0);
    expect(whenLogged[0]).toContain('xtool-flame');
    expect(whenHooked[0]).toContain('xtool-flame');
  });

  it('the webhook URL is a supervisor’s setting; its secret part is never shown', async () => {
    const { gw } = await setup();
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    expect((await consoleFetch(`${gw.url}/api/settings`, { headers: { cookie: otto } })).status).toBe(403);
    const r = await consoleFetch(`${gw.url}/api/settings`, { headers: { cookie: sam } });
    const text = await r.text();
    expect(text).not.toMatch(/secret-token/);
    expect(JSON.parse(text)).toMatchObject({ alarmWebhook: { set: true, fromEnvironment: true } });
    // Set by the environment: not changed from the page.
    const put = await consoleFetch(`${gw.url}/api/settings`, {
      method: 'PUT',
      headers: { cookie: sam, 'Content-Type': 'application/json' },
      body: JSON.stringify({ alarmWebhook: 'https://hooks.example.com/x' }),
    });
    expect(put.status).toBe(400);
    const test = await consoleFetch(`${gw.url}/api/settings/test-webhook`, {
      method: 'POST',
      headers: { cookie: sam },
    });
    expect(await test.json()).toEqual({ ok: true, result: 'delivered' });
  });
});
