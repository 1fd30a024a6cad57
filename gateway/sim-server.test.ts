import http from 'node:http';
import { afterEach, describe, expect, it } from 'vitest';
import { startSimFleet, startSimServer } from './sim-server';
import { openWs, startGateway, tempDir, testFamily, consoleFetch } from './test-util';
import { parseMachines } from './machines';
import { duetFamily } from '../src/controllers/duet/family';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

describe('simulator server', () => {
  it('serves a simulator over HTTP and WebSocket, with fault injection and controls', async () => {
    let pressed = 0;
    const fam = testFamily('prunt');
    const base = fam.createSimulator({ id: 'sim-1', name: 'Sim' });
    const s = await startSimServer({
      family: fam,
      id: 'sim-1',
      name: 'Sim',
      simulator: { ...base, controls: () => [{ id: 'button', label: 'Button', run: () => pressed++ }] },
    });
    cleanups.push(s.close);
    expect(await (await consoleFetch(`${s.url}/job?action=pause`)).json()).toMatchObject({
      path: '/job',
      action: 'pause',
    });
    expect((await consoleFetch(`${s.url}/missing`)).status).toBe(404);

    const post = (p: string, body?: unknown) =>
      consoleFetch(`${s.url}${p}`, {
        method: 'POST',
        body: body === undefined ? undefined : JSON.stringify(body),
      });
    expect(await (await post('/__sim/faults', { http5xx: true })).json()).toMatchObject({
      faults: { http5xx: true },
    });
    expect((await consoleFetch(`${s.url}/status`)).status).toBe(503);
    await post('/__sim/faults', { http5xx: false, malformed: true });
    const text = await (await consoleFetch(`${s.url}/status`)).text();
    expect(() => JSON.parse(text) as unknown).toThrow();
    await post('/__sim/faults', { malformed: false, drop: true });
    await expect(consoleFetch(`${s.url}/status`)).rejects.toThrow();
    await post('/__sim/faults', { drop: false });

    const w = await openWs(s.url.replace('http', 'ws') + '/live');
    expect(w.first).toBe('sim-hello 1');
    const closed = new Promise<number>((r) => w.ws.once('close', (code) => r(code)));
    await post('/__sim/close-sockets');
    expect(await closed).toBe(4000);

    expect((await post('/__sim/control/button')).status).toBe(200);
    expect(pressed).toBe(1);
    expect((await post('/__sim/control/nope')).status).toBe(404);
  });

  it('starts a fleet whose printed machines file is valid and works through the gateway', async () => {
    const fleet = await startSimFleet({ prunt: testFamily('prunt'), xtool: testFamily('xtool', 8081) });
    cleanups.push(fleet.close);
    const machines = parseMachines('sim', JSON.parse(JSON.stringify(fleet.machinesFile)) as unknown, {});
    expect(machines.map((m) => [m.id, m.kind, m.simulated])).toEqual([
      ['sim-prunt', 'prunt', false],
      ['sim-xtool', 'xtool', false],
    ]);
    expect(machines[1]?.wsUrl).not.toBeNull();
    expect(machines[1]?.wsUrl?.port).not.toBe(machines[1]?.url?.port);
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: { file: null, machines },
      families: { prunt: testFamily('prunt'), xtool: testFamily('xtool', 8081) },
      dataDir: t.dir,
      env: {},
    });
    cleanups.push(gw.close);
    expect(await (await consoleFetch(`${gw.url}/machines/sim-xtool/job?action=stop`)).json()).toMatchObject({
      sim: 'sim-xtool',
      action: 'stop',
    });
    const w = await openWs(`ws://${gw.host}/machines/sim-xtool/`);
    expect(w.first).toBe('sim-hello 1');
    w.ws.send('hi');
    expect(await w.next()).toBe('sim-echo:hi');
    await w.close();
  });

  it('counts upstream requests, TCP connections and sockets on both ports, not /__sim', async () => {
    const s = await startSimServer({ family: testFamily('xtool', 8081), id: 'sim-1', name: 'Sim' });
    cleanups.push(s.close);
    const agent = new http.Agent({ keepAlive: true, maxSockets: 1 });
    cleanups.push(() => agent.destroy());
    const get = (url: string, a: http.Agent | false): Promise<number> =>
      new Promise((resolve, reject) => {
        http
          .get(url, { agent: a, headers: { 'X-Shopdeck': '1' } }, (res) => {
            res.resume();
            res.on('end', () => resolve(res.statusCode ?? 0));
          })
          .on('error', reject);
      });
    expect(s.stats()).toEqual({ requests: 0, connections: 0, wsOpen: 0, wsOpened: 0, wsMaxOpen: 0 });

    // Three requests over one kept-alive connection, one on a connection of its own.
    for (let i = 0; i < 3; i++) expect(await get(`${s.url}/status`, agent)).toBe(200);
    expect(await get(`${s.url}/status`, false)).toBe(200);
    expect(s.stats()).toMatchObject({ requests: 4, connections: 2 });

    // The simulator's own endpoints are not controller traffic (their connection still is TCP).
    expect(await get(`${s.url}/__sim/controls`, agent)).toBe(200);
    expect(s.stats()).toMatchObject({ requests: 4, connections: 2 });

    // The separate WebSocket port: a plain request and a socket both count.
    expect(s.wsUrl).not.toBeNull();
    const wsHttp = (s.wsUrl ?? '').replace(/^ws/, 'http');
    expect(await get(`${wsHttp}/`, false)).toBe(426);
    const a = await openWs(`${s.wsUrl ?? ''}/`);
    const b = await openWs(`${s.url.replace('http', 'ws')}/live`);
    expect(s.stats()).toEqual({ requests: 5, connections: 5, wsOpen: 2, wsOpened: 2, wsMaxOpen: 2 });
    await a.close();
    await expect.poll(() => s.stats().wsOpen).toBe(1);

    s.resetStats();
    expect(s.stats()).toEqual({ requests: 0, connections: 0, wsOpen: 1, wsOpened: 0, wsMaxOpen: 1 });
    await b.close();
    await expect.poll(() => s.stats().wsOpen).toBe(0);
    expect(s.stats()).toMatchObject({ wsOpened: 0, wsMaxOpen: 1 });
  });

  it('npm run sim serves a standalone Duet (rr_*) beside the DSF one; the gateway finds out by probing', async () => {
    const fleet = await startSimFleet({ duet: duetFamily });
    cleanups.push(fleet.close);
    expect(fleet.machinesFile.machines.map((m) => m.id)).toEqual(['sim-duet', 'sim-duet-standalone']);
    const [dsf, rrf] = fleet.machinesFile.machines;
    // A real HTTP server speaking rr_* only.
    const c = (await (await consoleFetch(`${rrf?.url}/rr_connect?password=&sessionKey=yes`)).json()) as {
      err: number;
      sessionKey: number;
    };
    expect(c).toMatchObject({ err: 0, apiLevel: 2 });
    expect((await consoleFetch(`${rrf?.url}/rr_model?key=seqs`)).status).toBe(401);
    // DSF's paths get the board's web page (HTML, 200), as a real standalone board answers them.
    const page = await consoleFetch(`${rrf?.url}/machine/connect`);
    expect([page.status, page.headers.get('content-type')]).toEqual([200, 'text/html']);
    expect((await consoleFetch(`${dsf?.url}/rr_connect?sessionKey=yes`)).status).toBe(404);
    const machines = parseMachines('sim', JSON.parse(JSON.stringify(fleet.machinesFile)) as unknown, {});
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: { file: null, machines },
      families: { duet: duetFamily },
      dataDir: t.dir,
      env: {},
    });
    cleanups.push(gw.close);
    const viaGw = (id: string, p: string) => consoleFetch(`${gw.url}/machines/${id}${p}`);
    const a = (await (await viaGw('sim-duet-standalone', '/machine/connect')).json()) as Record<
      string,
      unknown
    >;
    expect(a).toMatchObject({ err: 0 });
    expect(a).not.toHaveProperty('sessionKey');
    const m = (await (
      await viaGw('sim-duet-standalone', '/rr_model?key=state.status&flags=')
    ).json()) as unknown;
    expect(m).toMatchObject({ result: 'idle' });
    const d = (await (await viaGw('sim-duet', '/machine/connect')).json()) as Record<string, unknown>;
    expect(d).not.toHaveProperty('err');
    expect((await viaGw('sim-duet', '/machine/model')).status).toBe(200);
  });
});
