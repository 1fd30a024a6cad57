import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import type { SimControl } from '../src/fleet/sim';
import { simPanelSchema, type SimPanel } from '../src/fleet/sim-panel';
import type { AuditEntry } from './audit';
import type { Families } from './context';
import type { MachineEntry } from './machines';
import {
  consoleFetch,
  login,
  openWs,
  startGateway,
  tempDir,
  testFamily,
  testSimulator,
  user,
  writeJson,
  type Running,
} from './test-util';

/**
 * `/api/sim/<id>` (sim-api.ts): the Simulator tab drives the gateway's own simulators. The
 * attacks are performed against the real gateway on a real HTTP server: a viewer or an operator
 * changing a simulator, a request without the console header (another site's form or fetch), a
 * machine that is not simulated.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function machine(id: string, simulated: boolean): MachineEntry {
  return {
    id,
    name: id,
    kind: 'prunt',
    simulated,
    url: simulated ? null : new URL('http://127.0.0.1:9'),
    wsUrl: null,
    secrets: {},
  };
}

/** The test family, whose simulators record their physical-world buttons and count themselves. */
function families(log: { pressed: string[]; created: number }): Families {
  return {
    prunt: {
      ...testFamily('prunt'),
      createSimulator: (o) => {
        log.created++;
        const controls: SimControl[] = [
          { id: 'button', label: 'Press the button', run: () => log.pressed.push(`${o.id}:button`) },
          { id: 'demo', label: 'Start a demo job', run: () => log.pressed.push(`${o.id}:demo`) },
        ];
        return { ...testSimulator(o.id), controls: () => controls };
      },
    },
  };
}

const PW = { vera: 'viewer-pass-1', otto: 'operator-pass-1', sam: 'supervisor-pass-1', lim: 'super-pass-2' };

interface Setup {
  gw: Running;
  log: { pressed: string[]; created: number };
  audit(): AuditEntry[];
}

async function setup(
  o: { secured?: boolean; machines?: MachineEntry[]; file?: string | null } = {},
): Promise<Setup> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = path.join(t.dir, 'users.json');
  if (o.secured)
    writeJson(usersFile, {
      users: [
        user('vera', 'viewer', PW.vera),
        user('otto', 'operator', PW.otto),
        user('sam', 'supervisor', PW.sam),
        // A supervisor of some machines only.
        user('lim', 'supervisor', PW.lim, { machines: ['p1'] }),
      ],
    });
  const log = { pressed: [] as string[], created: 0 };
  const gw = await startGateway({
    machines: {
      file: o.file === undefined ? '/etc/shopdeck/machines.json' : o.file,
      machines: o.machines ?? [machine('demo', true), machine('p1', false)],
    },
    families: families(log),
    dataDir: t.dir,
    usersFile,
    env: {},
  });
  cleanups.push(gw.close);
  return { gw, log, audit: () => gw.gw.audit.all() };
}

function get(s: Setup, id: string, cookie?: string): Promise<Response> {
  return consoleFetch(`${s.gw.url}/api/sim/${id}`, { headers: cookie ? { Cookie: cookie } : {} });
}

function post(
  s: Setup,
  id: string,
  body: unknown,
  o: { cookie?: string; headers?: Record<string, string>; consoleHeader?: boolean } = {},
): Promise<Response> {
  const send = o.consoleHeader === false ? fetch : consoleFetch;
  return send(`${s.gw.url}/api/sim/${id}`, {
    method: 'POST',
    headers: {
      'Content-Type': 'application/json',
      ...(o.cookie ? { Cookie: o.cookie } : {}),
      ...o.headers,
    },
    body: JSON.stringify(body),
  });
}

async function panel(r: Response): Promise<SimPanel> {
  expect(r.status).toBe(200);
  return simPanelSchema.parse(await r.json());
}

function valueOf(p: SimPanel, group: string, id: string): unknown {
  const c = p.controls.find((x) => x.group === group && x.id === id);
  return c && 'value' in c ? c.value : undefined;
}

describe('GET /api/sim/<id>', () => {
  it('describes the controls as data: the physical world, the faults with their values, a restart', async () => {
    const s = await setup();
    const p = await panel(await get(s, 'demo'));
    expect(p).toMatchObject({ machine: 'demo', kind: 'prunt' });
    expect(p.controls).toEqual([
      { group: 'world', id: 'button', type: 'action', label: 'Press the button' },
      { group: 'world', id: 'demo', type: 'action', label: 'Start a demo job' },
      { group: 'faults', id: 'drop', type: 'toggle', label: 'Drop connections', value: false },
      { group: 'faults', id: 'http5xx', type: 'toggle', label: 'Answer 503', value: false },
      { group: 'faults', id: 'malformed', type: 'toggle', label: 'Malformed bodies', value: false },
      {
        group: 'faults',
        id: 'latencyMs',
        type: 'choice',
        label: 'Latency',
        value: 0,
        choices: [0, 200, 1000, 3000, 10000],
        unit: 'ms',
      },
      { group: 'faults', id: 'closeSockets', type: 'action', label: 'Close sockets' },
      { group: 'simulator', id: 'reset', type: 'action', label: expect.stringContaining('Restart') },
    ]);
    // Reading writes nothing to the audit log.
    expect(s.audit()).toEqual([]);
  });
});

describe('POST /api/sim/<id> (open mode)', () => {
  it('sets a fault, runs a physical-world control, and audits each as a command on the machine', async () => {
    const s = await setup();
    expect((await consoleFetch(`${s.gw.url}/machines/demo/status`)).status).toBe(200);

    let p = await panel(await post(s, 'demo', { group: 'faults', id: 'http5xx', value: true }));
    expect(valueOf(p, 'faults', 'http5xx')).toBe(true);
    // The same simulator answers the machine's requests: every tab sees the fault.
    expect((await consoleFetch(`${s.gw.url}/machines/demo/status`)).status).toBe(503);
    p = await panel(await post(s, 'demo', { group: 'faults', id: 'http5xx', value: false }));
    expect(valueOf(p, 'faults', 'http5xx')).toBe(false);
    expect((await consoleFetch(`${s.gw.url}/machines/demo/status`)).status).toBe(200);

    p = await panel(await post(s, 'demo', { group: 'faults', id: 'latencyMs', value: 200 }));
    expect(valueOf(p, 'faults', 'latencyMs')).toBe(200);

    await panel(await post(s, 'demo', { group: 'world', id: 'button' }));
    expect(s.log.pressed).toEqual(['demo:button']);

    const sim = s.audit().filter((e) => e.commandId?.startsWith('sim.'));
    expect(sim).toMatchObject([
      {
        type: 'command',
        result: 'ok',
        user: 'anonymous',
        source: 'gateway',
        machine: 'demo',
        method: 'POST',
        path: '/api/sim/demo',
        commandId: 'sim.faults.http5xx',
        label: 'Simulator: Answer 503: on',
      },
      { commandId: 'sim.faults.http5xx', label: 'Simulator: Answer 503: off' },
      { commandId: 'sim.faults.latencyMs', label: 'Simulator: Latency: 200 ms' },
      { commandId: 'sim.world.button', label: 'Simulator: Press the button' },
    ]);
  });

  it('drops connections and closes sockets of the simulated machine', async () => {
    const s = await setup();
    const w = await openWs(`ws://${s.gw.host}/machines/demo/live`);
    expect(w.first).toBe('sim-hello 1');
    const closed = new Promise<number>((r) => w.ws.once('close', (code) => r(code)));
    await panel(await post(s, 'demo', { group: 'faults', id: 'closeSockets' }));
    expect(await closed).toBe(4000);
    await panel(await post(s, 'demo', { group: 'faults', id: 'drop', value: true }));
    await expect(consoleFetch(`${s.gw.url}/machines/demo/status`)).rejects.toThrow();
  });

  it('refuses what is not a control, or a value of the wrong kind (400), and changes nothing', async () => {
    const s = await setup();
    for (const body of [
      { group: 'world', id: 'self-destruct' },
      { group: 'world', id: 'button', value: true },
      { group: 'faults', id: 'http5xx' },
      { group: 'faults', id: 'http5xx', value: 1 },
      { group: 'faults', id: 'latencyMs', value: 123 },
      { group: 'faults', id: 'latencyMs', value: true },
      { group: 'faults', id: 'faults' },
      { group: 'simulator', id: 'format-disk' },
      { group: 'elsewhere', id: 'button' },
      { group: 'world', id: 'button', extra: 'no' },
      'button',
    ]) {
      const r = await post(s, 'demo', body);
      expect(r.status, JSON.stringify(body)).toBe(400);
    }
    expect(s.log.pressed).toEqual([]);
    const p = await panel(await get(s, 'demo'));
    expect(
      p.controls.filter((c) => c.group === 'faults').map((c) => ('value' in c ? c.value : null)),
    ).toEqual([false, false, false, 0, null]);
    expect(s.audit().filter((e) => e.type === 'command')).toEqual([]);
  });

  it('restarts the simulator: a fresh world without faults, its sockets closed', async () => {
    const s = await setup();
    await panel(await post(s, 'demo', { group: 'faults', id: 'http5xx', value: true }));
    expect(s.log.created).toBe(1);
    const w = await openWs(`ws://${s.gw.host}/machines/demo/live`);
    const closed = new Promise<number>((r) => w.ws.once('close', (code) => r(code)));
    const p = await panel(await post(s, 'demo', { group: 'simulator', id: 'reset' }));
    expect(await closed).toBe(4000);
    expect(valueOf(p, 'faults', 'http5xx')).toBe(false);
    expect(s.log.created).toBe(2);
    expect((await consoleFetch(`${s.gw.url}/machines/demo/status`)).status).toBe(200);
    expect(s.audit().at(-1)).toMatchObject({ commandId: 'sim.simulator.reset', machine: 'demo' });
  });
});

describe('the built-in demo fleet', () => {
  it('runs each simulator’s demo job once, in the gateway, and again after a restart', async () => {
    const s = await setup({ file: null, machines: [machine('demo-a', true), machine('demo-b', true)] });
    await new Promise((r) => setTimeout(r, 1800));
    expect(s.log.pressed.sort()).toEqual(['demo-a:demo', 'demo-b:demo']);
    await panel(await post(s, 'demo-a', { group: 'simulator', id: 'reset' }));
    expect(s.log.pressed.sort()).toEqual(['demo-a:demo', 'demo-a:demo', 'demo-b:demo']);
  });

  it('runs no demo job for a machines file', async () => {
    const s = await setup({ machines: [machine('demo-a', true)] });
    await new Promise((r) => setTimeout(r, 1800));
    expect(s.log.pressed).toEqual([]);
  });
});

describe('attacks on /api/sim/<id> (secured mode)', () => {
  it('a viewer or an operator cannot change a simulator, nor read it; the refusal is audited', async () => {
    const s = await setup({ secured: true });
    for (const [name, pw] of [
      ['vera', PW.vera],
      ['otto', PW.otto],
    ] as const) {
      const cookie = await login(s.gw.url, name, pw);
      const r = await post(s, 'demo', { group: 'faults', id: 'drop', value: true }, { cookie });
      expect(r.status).toBe(403);
      expect(await r.json()).toMatchObject({ needs: 'supervisor' });
      expect((await post(s, 'demo', { group: 'world', id: 'button' }, { cookie })).status).toBe(403);
      expect((await post(s, 'demo', { group: 'simulator', id: 'reset' }, { cookie })).status).toBe(403);
      expect((await get(s, 'demo', cookie)).status).toBe(403);
      // …while the simulated machine itself answers them as hardware would (their role permits reads).
      expect(
        (await consoleFetch(`${s.gw.url}/machines/demo/status`, { headers: { Cookie: cookie } })).status,
      ).toBe(200);
    }
    expect(s.log.pressed).toEqual([]);
    expect(s.log.created).toBe(1);
    const sam = await login(s.gw.url, 'sam', PW.sam);
    expect(valueOf(await panel(await get(s, 'demo', sam)), 'faults', 'drop')).toBe(false);
    const refused = s.audit().filter((e) => e.type === 'refused');
    // Three changes and one read, for each of the two.
    expect(refused).toHaveLength(8);
    expect(refused.filter((e) => e.method === 'GET').map((e) => [e.user, e.path])).toEqual([
      ['vera', '/api/sim/demo'],
      ['otto', '/api/sim/demo'],
    ]);
    expect(refused[0]).toMatchObject({
      result: 'refused',
      user: 'vera',
      machine: 'demo',
      method: 'POST',
      path: '/api/sim/demo',
      role: 'supervisor',
    });
    expect(s.audit().filter((e) => e.type === 'command')).toEqual([]);
  });

  it('without a session: 401, nothing changes', async () => {
    const s = await setup({ secured: true });
    const r = await post(s, 'demo', { group: 'faults', id: 'drop', value: true });
    expect(r.status).toBe(401);
    expect(await r.json()).toMatchObject({ login: true });
    expect((await get(s, 'demo')).status).toBe(401);
    expect(s.log.created).toBe(0);
  });

  it('a supervisor’s request without the console header (another site) is refused, nothing changes', async () => {
    const s = await setup({ secured: true });
    const sam = await login(s.gw.url, 'sam', PW.sam);
    const attempts: Array<{ headers?: Record<string, string>; consoleHeader?: boolean }> = [
      // A form or a fetch from another site cannot add the header…
      { consoleHeader: false },
      { consoleHeader: false, headers: { 'Sec-Fetch-Site': 'cross-site', Origin: 'http://evil.example' } },
      // …and with it, the browser's own word on where the request comes from still counts.
      { headers: { 'Sec-Fetch-Site': 'same-site' } },
      { headers: { Origin: 'http://evil.example' } },
      { headers: { 'X-Shopdeck': '0' } },
    ];
    for (const a of attempts) {
      const r = await post(s, 'demo', { group: 'faults', id: 'drop', value: true }, { cookie: sam, ...a });
      expect(r.status, JSON.stringify(a)).toBe(403);
      expect(await r.json()).toMatchObject({ crossSite: true });
    }
    const p = await panel(await get(s, 'demo', sam));
    expect(valueOf(p, 'faults', 'drop')).toBe(false);
    expect(s.audit().filter((e) => e.type === 'refused')).toHaveLength(attempts.length);
    // The console's own request goes through.
    const ok = await post(s, 'demo', { group: 'faults', id: 'drop', value: true }, { cookie: sam });
    expect(valueOf(await panel(ok), 'faults', 'drop')).toBe(true);
    expect(s.audit().at(-1)).toMatchObject({ type: 'command', user: 'sam', commandId: 'sim.faults.drop' });
  });

  it('a machine that is not simulated, unknown, or not the supervisor’s answers 404', async () => {
    const s = await setup({ secured: true });
    const sam = await login(s.gw.url, 'sam', PW.sam);
    const lim = await login(s.gw.url, 'lim', PW.lim);
    expect((await get(s, 'p1', sam)).status).toBe(404);
    expect((await post(s, 'p1', { group: 'faults', id: 'drop', value: true }, { cookie: sam })).status).toBe(
      404,
    );
    expect((await post(s, 'p1', { group: 'simulator', id: 'reset' }, { cookie: sam })).status).toBe(404);
    expect((await get(s, 'nope', sam)).status).toBe(404);
    expect((await get(s, '..%2Fp1', sam)).status).toBe(404);
    // lim supervises p1 only: the simulated demo is not one of lim's machines.
    expect((await get(s, 'demo', lim)).status).toBe(404);
    expect((await post(s, 'demo', { group: 'world', id: 'button' }, { cookie: lim })).status).toBe(404);
    expect(s.log.pressed).toEqual([]);
    expect(s.log.created).toBe(0);
  });
});
