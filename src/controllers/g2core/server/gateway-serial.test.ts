import path from 'node:path';
import { SerialPortMock } from 'serialport';
import type { BoardSim } from './board-sim';
import { afterEach, describe, expect, it } from 'vitest';
import { g2coreFamily as g2coreDescriptor } from '../family';
import { g2coreServer } from '.';
import {
  consoleFetch,
  login,
  startGateway,
  tempDir,
  user,
  writeJson,
  type Running,
} from '../../../../gateway/test-util';
import { mockBoard, type MockBoard } from './test-board';
import type { GatewayOptions } from '../../../../gateway/context';
import type { NodeFamily } from '../../../fleet/server-part';

/** The family as src/controllers/families.ts lists it: with its server part. */
const g2coreFamily: NodeFamily = { ...g2coreDescriptor, server: g2coreServer };

/** The lines the board read, without the status requests that ask a quiet board whether it lives (the setup's sv and si first). */
function boardRead(board: BoardSim): string[] {
  return board.received.filter((l) => l !== '{"sr":null}');
}

/**
 * A serial g2core behind the whole gateway: the proxy routes `/machines/<id>/…` to the bridge as
 * it does to a simulator, so the role rules of the REST path and the audit apply unchanged (the
 * attacks: a viewer's job start, an operator's settings write and board reset, a forged
 * cross-site request). The board is SIMULATED on the serialport mock binding; time is the board's
 * own (short moves), and the test waits for states, never for a wall-clock duration.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
  SerialPortMock.binding.reset();
});

const PASS = { vera: 'viewer-pass-1', otto: 'operator-pass-1', sam: 'supervisor-pass-1' };

type Cookies = Record<'vera' | 'otto' | 'sam', string>;

async function setup(
  msPerLine = 5,
  more: Partial<GatewayOptions> = {},
): Promise<{ gw: Running; mb: MockBoard; as: Cookies }> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = writeJson(path.join(t.dir, 'users.json'), {
    users: [
      user('vera', 'viewer', PASS.vera),
      user('otto', 'operator', PASS.otto),
      user('sam', 'supervisor', PASS.sam),
    ],
  });
  SerialPortMock.binding.reset();
  const mb = mockBoard('/dev/ttyACM0', { msPerLine });
  const gw = await startGateway({
    machines: {
      file: null,
      machines: [
        {
          id: 'mill',
          name: 'Mill',
          kind: 'g2core',
          simulated: false,
          url: null,
          wsUrl: null,
          secrets: {},
          serial: { path: '/dev/ttyACM0', baudRate: 115200 },
        },
      ],
    },
    families: { g2core: g2coreFamily },
    serialOpener: mb.opener,
    dataDir: t.dir,
    usersFile,
    env: {},
    ...more,
  });
  cleanups.push(gw.close);
  const as: Cookies = {
    vera: await login(gw.url, 'vera', PASS.vera),
    otto: await login(gw.url, 'otto', PASS.otto),
    sam: await login(gw.url, 'sam', PASS.sam),
  };
  return { gw, mb, as };
}

async function until(check: () => Promise<boolean>, what: string): Promise<void> {
  for (let i = 0; i < 200; i++) {
    if (await check()) return;
    await new Promise((r) => setTimeout(r, 20));
  }
  throw new Error(`never: ${what}`);
}

function req(gw: Running, cookie: string, method: string, p: string, body?: unknown): Promise<Response> {
  return consoleFetch(`${gw.url}/machines/mill${p}`, {
    method,
    headers: { cookie, ...(body === undefined ? {} : { 'Content-Type': 'application/json' }) },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
}

describe('serial g2core through the gateway', () => {
  it('opens the port at start, answers the REST design, and enforces the REST role rules', async () => {
    const { gw, mb, as } = await setup();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    expect(await (await req(gw, as.vera, 'GET', '/version')).json()).toMatchObject({ fb: 101.03 });

    const job = await req(gw, as.otto, 'POST', '/job', { name: 'p.nc', gcode: 'G1 X1 F100\nG1 X2\nG1 X3' });
    expect(job.status).toBe(201);
    // A viewer may not start it, nor hold it; an operator may.
    expect((await req(gw, as.vera, 'PUT', '/job/1', { state: 'run' })).status).toBe(403);
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    await until(
      async () =>
        ((await (await req(gw, as.vera, 'GET', '/job/1')).json()) as { state: string }).state === 'done',
      'job done',
    );
    expect(boardRead(mb.board).slice(2)).toEqual(['G1 X1 F100', 'G1 X2', 'G1 X3']);

    // Settings are the supervisor's; so is the G-code console; so is the board reset.
    expect((await req(gw, as.otto, 'PUT', '/machine/x/vm', 100)).status).toBe(403);
    expect(
      (await req(gw, as.otto, 'POST', '/operation', { optype: 'run', value: ['M3 S1000'] })).status,
    ).toBe(403);
    expect((await req(gw, as.otto, 'POST', '/board/reset')).status).toBe(403);
    expect(mb.board.controls).not.toContain('\x18');
    expect((await req(gw, as.sam, 'PUT', '/machine/x/vm', 100)).status).toBe(200);
    expect((await req(gw, as.sam, 'POST', '/board/reset')).status).toBe(200);
    expect(mb.board.controls).toContain('\x18');

    // A cross-site request (no X-Shopdeck header) never reaches the board.
    const before = boardRead(mb.board).length;
    const forged = await fetch(`${gw.url}/machines/mill/operation`, {
      method: 'POST',
      headers: { cookie: as.sam, 'Content-Type': 'text/plain' },
      body: JSON.stringify({ optype: 'run', value: ['G0 X100'] }),
    });
    expect(forged.status).toBe(403);
    expect(boardRead(mb.board).length).toBe(before);

    // The commands are in the audit log with who sent them.
    const cmds = gw.gw.audit.all().filter((e) => e.type === 'command' && e.machine === 'mill');
    expect(cmds.map((e) => [e.user, e.method, e.path?.split('?')[0]])).toEqual(
      expect.arrayContaining([
        ['otto', 'POST', '/job'],
        ['otto', 'PUT', '/job/1'],
        ['sam', 'PUT', '/machine/x/vm'],
        ['sam', 'POST', '/board/reset'],
      ]),
    );
  });

  it('a character whose byte is a control (U+0118 is ^X) is refused with 400 naming the line, in a job, MDI and a setting: nothing reaches the board', async () => {
    const { gw, mb, as } = await setup();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    await until(async () => boardRead(mb.board).length >= 2, 'the setup read');
    const received = boardRead(mb.board).length;
    // The operator's job that would reset the board (a supervisor-only action): not plain G-code,
    // refused by the gateway's rule for jobs, the line named.
    const op = await req(gw, as.otto, 'POST', '/job', { name: 'p.nc', gcode: 'G90\nG0 X1 \u0118' });
    expect(op.status).toBe(403);
    expect(((await op.json()) as { error: string }).error).toMatch(/line 2 .*outside printable ASCII/);
    // A supervisor's is refused by the bridge, which checks the bytes it would write.
    const job = await req(gw, as.sam, 'POST', '/job', { name: 'p.nc', gcode: 'G90\nG0 X1 \u0118' });
    expect(job.status).toBe(400);
    expect(await job.json()).toMatchObject({
      status: { code: 101, additional_description: expect.stringMatching(/^line 2: .*U\+0118 .*\^X/) },
    });
    // The supervisor's MDI (kill) and setting ("~" cycle start) are refused the same way.
    const mdi = await req(gw, as.sam, 'POST', '/operation', { optype: 'run', value: ['G0 X1 \u0104 Y1'] });
    expect(mdi.status).toBe(400);
    expect(JSON.stringify(await mdi.json())).toMatch(/line 1: .*\^D/);
    expect((await req(gw, as.sam, 'PUT', '/machine/x/vm', '5\u017e')).status).toBe(400);
    await new Promise((r) => setTimeout(r, 100));
    expect(boardRead(mb.board).length).toBe(received);
    expect(mb.board.controls).toEqual([]);
    expect(mb.board.stat).toBe(1);
  });

  it("an operator's job of settings or JSON writes is refused with the line named, nothing written; a supervisor's runs; a plain multipart upload is the operator's", async () => {
    const { gw, mb, as } = await setup();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    await until(async () => boardRead(mb.board).length >= 2, 'the setup read');
    const received = boardRead(mb.board).length;
    for (const bad of ['G90\n$defa=1', 'G90\n{"xsn":0}', 'G90\nG10 L2 P1 X5', 'G90\nM100 ({"xvm":1})']) {
      const r = await req(gw, as.otto, 'POST', '/job', { name: 'evil.nc', gcode: bad });
      expect(r.status, bad).toBe(403);
      const body = (await r.json()) as { error: string };
      expect(body.error, bad).toMatch(
        /^queue a job whose line 2 ".*" is .*needs the supervisor role \(otto is operator\)/,
      );
    }
    // Multipart, as the page uploads a file.
    const form = new FormData();
    form.append('file', new Blob(['G90\n$defa=1\n']), 'evil.nc');
    form.append('name', 'evil.nc');
    const up = await consoleFetch(`${gw.url}/machines/mill/job`, {
      method: 'POST',
      headers: { cookie: as.otto },
      body: form,
    });
    expect(up.status).toBe(403);
    expect(((await up.json()) as { error: string }).error).toMatch(/line 2 "\$defa=1"/);
    expect(((await (await req(gw, as.vera, 'GET', '/job')).json()) as unknown[]).length).toBe(0);
    await new Promise((r) => setTimeout(r, 50));
    expect(boardRead(mb.board).length).toBe(received);
    const refused = gw.gw.audit.all().filter((e) => e.type === 'refused' && e.path === '/job');
    expect(refused.map((e) => e.user)).toEqual(['otto', 'otto', 'otto', 'otto', 'otto']);

    // The operator's plain file is queued and runs.
    const plain = new FormData();
    plain.append('file', new Blob(['G90\nG1 X1 F100\n']), 'ok.nc');
    plain.append('name', 'ok.nc');
    const ok = await consoleFetch(`${gw.url}/machines/mill/job`, {
      method: 'POST',
      headers: { cookie: as.otto },
      body: plain,
    });
    expect(ok.status).toBe(201);
    // The supervisor's settings job is queued, and an operator may start it (the upload was the approval).
    const sup = await req(gw, as.sam, 'POST', '/job', { name: 'setup.nc', gcode: '{"xvm":5000}\nG90' });
    expect(sup.status).toBe(201);
    const id = String(await sup.json());
    expect((await req(gw, as.otto, 'PUT', `/job/${id}`, { state: 'run' })).status).toBe(200);
    await until(async () => mb.board.received.includes('{"xvm":5000}'), 'the supervisor job ran');
  });

  it('streams a 200-line job through the gateway with a hold, a resume and a kill: exact bytes, at most 4 lines in flight', async () => {
    const { gw, mb, as } = await setup(50);
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    const lines = Array.from({ length: 200 }, (_, i) => `G1 X${i + 1} F1000`);
    expect((await req(gw, as.otto, 'POST', '/job', { name: 'big.nc', gcode: lines.join('\n') })).status).toBe(
      201,
    );
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    const job = async (): Promise<{ state: string; done: number }> =>
      (await (await req(gw, as.vera, 'GET', '/job/1')).json()) as { state: string; done: number };
    await until(async () => (await job()).done >= 20, '20 lines');
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'pause' })).status).toBe(200);
    await until(async () => mb.board.stat === 6, 'held');
    const held = boardRead(mb.board).length;
    await new Promise((r) => setTimeout(r, 200));
    expect(boardRead(mb.board).length).toBeLessThanOrEqual(held + 4); // at most the lines in flight
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    await until(async () => (await job()).done >= held + 10, '10 more lines');
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'kill' })).status).toBe(200);
    await until(async () => (await job()).state === 'killed', 'killed');
    expect(mb.board.controls).toEqual(['!', '~', '!', '%', '\x04']);
    const read = boardRead(mb.board).slice(2);
    expect(read.length).toBeLessThan(200);
    expect(read).toEqual(lines.slice(0, read.length));
    expect(mb.board.maxPending).toBeLessThanOrEqual(4);
    const who = gw.gw.audit
      .all()
      .filter((e) => e.type === 'command' && e.path === '/job/1')
      .map((e) => e.user);
    expect(who).toEqual(['otto', 'otto', 'otto', 'otto']);
  });

  it('pages opened through the gateway during a job and during a hold read the machine at once; one resumes the job; the job ends done with every line once', async () => {
    const { gw, mb, as } = await setup(10);
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    const lines = Array.from({ length: 150 }, (_, i) => `G1 X${(i % 30) + 1} Y${i} F1000`);
    expect((await req(gw, as.otto, 'POST', '/job', { name: 'p.nc', gcode: lines.join('\n') })).status).toBe(
      201,
    );
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    await until(async () => mb.board.waiting > 0, 'lines waiting in the board (the planner full)');
    for (let page = 0; page < 10; page++) {
      const who = [as.vera, as.otto, as.sam][page % 3]!;
      const [tree, x, sr] = await Promise.all([
        req(gw, who, 'GET', '/machine'),
        req(gw, who, 'GET', '/machine/x'),
        req(gw, who, 'GET', '/status_report'),
      ]);
      expect([tree.status, x.status, sr.status]).toEqual([200, 200, 200]);
    }
    expect(((await (await req(gw, as.vera, 'GET', '/job/1')).json()) as { state: string }).state).toBe(
      'running',
    );
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'pause' })).status).toBe(200);
    await until(async () => mb.board.stat === 6, 'held');
    await new Promise((r) => setTimeout(r, 300));
    // A page opened during the hold: Hold at once, the settings readable, and Cycle start from it.
    expect(await (await req(gw, as.vera, 'GET', '/status_report')).json()).toMatchObject({ stat: 6 });
    expect((await req(gw, as.vera, 'GET', '/machine')).status).toBe(200);
    expect((await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    await until(
      async () =>
        ((await (await req(gw, as.vera, 'GET', '/job/1')).json()) as { state: string }).state !== 'running',
      'the job ended',
    );
    expect(await (await req(gw, as.vera, 'GET', '/job/1')).json()).toMatchObject({
      state: 'done',
      done: 150,
    });
    expect(mb.board.received.filter((l) => !l.startsWith('{'))).toEqual(lines);
    expect(mb.board.maxPending).toBeLessThanOrEqual(4);
  });

  it('an unplugged board answers 503 with the reason at once, and the page sees it come back', async () => {
    const { gw, mb, as } = await setup();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    mb.unplug();
    const r = await req(gw, as.otto, 'POST', '/operation', { optype: 'run', value: ['G91 G0 X1'] });
    expect(r.status).toBe(503);
    // The gateway's own failure, marked as such for the page and the watch.
    expect(r.headers.get('x-shopdeck-gateway')).toBe('error');
    const body = (await r.json()) as { error: string; gateway: boolean };
    expect(body.gateway).toBe(true);
    expect(body.error).toMatch(/Mill: the board went away/);
    mb.replug();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'back online');
    // The jog sent while unplugged was never sent later.
    expect(boardRead(mb.board).filter((l) => l.startsWith('G91'))).toEqual([]);
  });

  it('stuck in run: the machine page reads why, the watch raises an alarm, a supervisor resets the board', async () => {
    const watch = g2coreFamily.gateway?.sharing?.watch;
    const sharing = g2coreFamily.gateway?.sharing;
    if (!watch || !sharing) throw new Error('the g2core family declares no watch');
    const family: NodeFamily = {
      ...g2coreFamily,
      gateway: { ...g2coreFamily.gateway, sharing: { ...sharing, watch: { ...watch, everyMs: 100 } } },
    };
    const { gw, mb, as } = await setup(100, {
      watch: true,
      serialWatchdogMs: 600,
      families: { g2core: family },
    });
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200, 'online');
    const lines = Array.from({ length: 100 }, (_, i) => `G1 X${i + 1} F1000`);
    await req(gw, as.otto, 'POST', '/job', { name: 'long.nc', gcode: lines.join('\n') });
    await req(gw, as.otto, 'PUT', '/job/1', { state: 'run' });
    await until(async () => mb.board.stat === 5, 'running');
    await new Promise((r) => setTimeout(r, 300)); // the watch sees it running
    mb.board.stuckInRun();
    await until(async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 503, 'stuck');
    const body = (await (await req(gw, as.vera, 'GET', '/status_report')).json()) as { error: string };
    expect(body.error).toMatch(/stuck in run.*supervisor can reset the board/);
    await until(
      async () =>
        gw.gw.alarms
          .query({ machines: null, machine: 'mill' })
          .some((a) => a.key === 'offline-during-job' && a.clearedAt === null),
      'the "offline during a job" alarm in the alarm centre',
    );
    expect((await req(gw, as.otto, 'POST', '/board/reset')).status).toBe(403);
    expect((await req(gw, as.sam, 'POST', '/board/reset')).status).toBe(200);
    await until(
      async () => (await req(gw, as.vera, 'GET', '/status_report')).status === 200,
      'back after the reset',
    );
    expect(((await (await req(gw, as.vera, 'GET', '/job/1')).json()) as { state: string }).state).toBe(
      'error',
    );
  });
});
