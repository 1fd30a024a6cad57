import { afterEach, describe, expect, it } from 'vitest';
import {
  consoleFetch,
  gatewayFor,
  login,
  stubEntry,
  stubFor,
  user,
  type Cleanups,
} from '../../../gateway/test-util';
import { g2coreFamily } from './family';

/**
 * An operator's job on a REST-design g2core (the gateway forwards `POST /job` to the controller):
 * the gateway reads the job and refuses, naming the line, any job that is not plain G-code before
 * anything is forwarded. The controller is a stub that records what reaches it. A simulated
 * g2core goes the same way (the proxy classifies before the simulator answers).
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PASS = { otto: 'operator-pass-1', sam: 'supervisor-pass-1' };

async function rig(simulated = false) {
  const stub = await stubFor(cleanups);
  stub.respond = (_req, res) => {
    res.writeHead(201, { 'Content-Type': 'application/json' });
    res.end('7');
  };
  const gw = await gatewayFor(
    cleanups,
    [
      simulated
        ? stubEntry('cnc', null, { kind: 'g2core', simulated: true })
        : stubEntry('cnc', stub.url, { kind: 'g2core' }),
    ],
    {
      families: { g2core: g2coreFamily },
      users: [user('otto', 'operator', PASS.otto), user('sam', 'supervisor', PASS.sam)],
    },
  );
  const as = { otto: await login(gw.url, 'otto', PASS.otto), sam: await login(gw.url, 'sam', PASS.sam) };
  const post = (cookie: string, body: unknown): Promise<Response> =>
    consoleFetch(`${gw.url}/machines/cnc/job`, {
      method: 'POST',
      headers: { cookie, 'Content-Type': 'application/json' },
      body: JSON.stringify(body),
    });
  const upload = (cookie: string, text: string): Promise<Response> => {
    const form = new FormData();
    form.append('file', new Blob([text]), 'part.nc');
    form.append('name', 'part.nc');
    return consoleFetch(`${gw.url}/machines/cnc/job`, { method: 'POST', headers: { cookie }, body: form });
  };
  return { stub, gw, as, post, upload };
}

describe('g2core jobs through the gateway: an operator queues plain G-code only', () => {
  it('REST design: an operator\'s "$defa=1" or {"xsn":0} job is refused naming the line, never forwarded; a supervisor\'s is', async () => {
    const { stub, gw, as, post, upload } = await rig();
    for (const [gcode, line] of [
      ['G90\nG0 X1\n$defa=1', 3],
      ['{"xsn":0}\nG0 X1', 1],
      ['G21\nG10 L20 P1 X0 Y0', 2],
    ] as const) {
      const r = await post(as.otto, { name: 'evil.nc', gcode });
      expect(r.status, gcode).toBe(403);
      expect(((await r.json()) as { error: string }).error).toMatch(
        new RegExp(`^queue a job whose line ${line} ".*" is .*needs the supervisor role`),
      );
    }
    const file = await upload(as.otto, 'G90\r\nG0 X1\r\n$xvm=99999\r\n');
    expect(file.status).toBe(403);
    expect(((await file.json()) as { error: string }).error).toMatch(
      /line 3 "\$xvm=99999" is a settings write/,
    );
    expect(stub.seen.filter((s) => s.url.startsWith('/job'))).toEqual([]);
    expect(
      gw.gw.audit
        .all()
        .filter((e) => e.type === 'refused' && e.machine === 'cnc')
        .map((e) => [e.user, e.method, e.path]),
    ).toEqual(Array.from({ length: 4 }, () => ['otto', 'POST', '/job']));

    // Allowed: the operator's plain job (JSON and multipart, forwarded byte for byte), the supervisor's settings job.
    expect((await post(as.otto, { name: 'ok.nc', gcode: 'G90\nG1 X1 F100' })).status).toBe(201);
    expect((await upload(as.otto, 'G90\nG1 X2 F100\n')).status).toBe(201);
    expect((await post(as.sam, { name: 'setup.nc', gcode: '$defa=1' })).status).toBe(201);
    const jobs = stub.seen.filter((s) => s.url === '/job');
    expect(jobs).toHaveLength(3);
    expect(jobs[0]?.body).toBe(JSON.stringify({ name: 'ok.nc', gcode: 'G90\nG1 X1 F100' }));
    expect(jobs[1]?.body).toContain('G90\nG1 X2 F100\n');
    expect(jobs[1]?.headers['content-type']).toMatch(/^multipart\/form-data; boundary=/);
    expect(jobs[2]?.body).toContain('$defa=1');
  });

  it('a simulated g2core: the same rule before the simulator answers', async () => {
    const { gw, as, post } = await rig(true);
    expect((await post(as.otto, { name: 'evil.nc', gcode: 'G90\n$defa=1' })).status).toBe(403);
    expect((await post(as.otto, { name: 'ok.nc', gcode: 'G90\nG1 X1 F100' })).status).toBe(201);
    const list = (await (
      await consoleFetch(`${gw.url}/machines/cnc/job`, { headers: { cookie: as.otto } })
    ).json()) as Array<{ name: string }>;
    expect(list.map((j) => j.name)).toEqual(['ok.nc']);
  });
});
