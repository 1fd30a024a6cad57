import { afterEach, describe, expect, it } from 'vitest';
import path from 'node:path';
import {
  consoleFetch,
  login,
  openWs,
  startGateway,
  tempDir,
  user,
  writeJson,
} from '../../../gateway/test-util';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { duetFamily } from './family';
import { DuetSession } from './session';
import { FILELIST_PAGE, MAX_SESSIONS, RrfSimulator } from './sim/standalone';
import { duetRig, until } from '../../../gateway/test-util-duet';

/**
 * Issue 20: a Duet without an SBC (standalone RepRapFirmware, `rr_*`) through the real gateway.
 * The machine has no `api` in the machines file: the gateway probes `rr_connect` (as Duet Web
 * Control does), holds the standalone session, and the page learns the API from the connect
 * answer; every Duet page then works on the polled model.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const rig = (simPassword: string | null, configured?: string) =>
  duetRig({
    id: 'rsim',
    name: 'Duet 2',
    configured,
    simulated: true,
    makeSim: (o) => new RrfSimulator({ ...o, password: simPassword, tickMs: 100 }),
    cleanups,
  });

const status = (s: DuetSession) => s.store.getState().model?.state.status;

describe('a standalone Duet (rr_*) through the gateway', () => {
  it('is probed and polled: online, the model merged, no key in the page, replies in the log', async () => {
    const { sim, session, ctx } = await rig('rrf-pass-1', 'rrf-pass-1');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(session.client.api).toBe('standalone');
    expect(session.store.getState().transport).toBe('standalone');
    expect(session.client.sessionKey).toBeNull();
    const model = session.store.getState().model;
    // The rig's fleet has no machines file: the built-in demo, whose job may have started already.
    expect(model?.state.status).toMatch(/^(idle|processing)$/);
    expect(model?.heat.heaters.length).toBeGreaterThan(0);
    expect(model?.volumes.length).toBeGreaterThan(0);
    // Only the rr_* API reached the board; one session (the gateway's) for the page.
    expect(sim().requests.some((r) => r.includes('/machine/'))).toBe(false);
    expect(sim().requests).toContain('GET /rr_model');
    expect(sim().openSessions).toBe(1);
    // A console code goes by rr_gcode; its reply comes by rr_reply into the console log.
    const r = await ctx.commands.run(session.cmd.console, { code: 'M115' });
    expect(sim().printer.codes).toEqual(['M115']);
    expect(JSON.stringify(r)).toMatch(/FIRMWARE_NAME/);
    expect(ctx.log.store.getState().entries.some((e) => /FIRMWARE_NAME/.test(e.text))).toBe(true);
  });

  it('three pages on one board during a job: each code’s reply reaches only the page that sent it, the board’s messages every page; the board is asked for replies by the gateway alone', async () => {
    const { sim, session, ctx } = await rig(null);
    const page = (name: string, role: 'viewer' | 'supervisor') => {
      const c = createContext(
        { id: 'rsim', name: 'Duet 2', kind: 'duet', simulated: true },
        { visibility: alwaysVisible, principal: () => ({ name, role }) },
      );
      const s = new DuetSession(c);
      cleanups.push(() => s.stop());
      return { c, s };
    };
    const b = page('wall', 'viewer');
    const c = page('sue', 'supervisor');
    session.start();
    b.s.start();
    c.s.start();
    const online = (x: typeof ctx) => x.snapshot.getState().link === 'online';
    await until(() => online(ctx) && online(b.c) && online(c.c));
    // A job runs (its start is the board's own message).
    sim()
      .printer.controls()
      .find((x) => x.id === 'demo')
      ?.run();
    await until(() => status(session) === 'processing');
    const logged = (x: typeof ctx, re: RegExp): number =>
      x.log.store.getState().entries.filter((e) => re.test(e.text)).length;
    // Page A sends five codes, page C one of its own in between.
    const replies: string[] = [];
    for (let i = 1; i <= 5; i++) {
      replies.push(JSON.stringify(await ctx.commands.run(session.cmd.console, { code: 'M115' })));
      if (i === 3) {
        const r = await c.c.commands.run(c.s.cmd.console, { code: 'M42' });
        expect(JSON.stringify(r)).toMatch(/M42: Command is not supported/);
      }
    }
    // Every one of A's five replies came to A.
    expect(replies.filter((r) => /FIRMWARE_NAME/.test(r))).toHaveLength(5);
    // The board's own message (a warning now) reaches every page.
    sim()
      .printer.controls()
      .find((x) => x.id === 'warning')
      ?.run();
    for (const x of [ctx, b.c, c.c]) await until(() => logged(x, /phase A may be disconnected/) === 1);
    // Nobody else saw A's replies, nor C's.
    expect(logged(b.c, /FIRMWARE_NAME/)).toBe(0);
    expect(logged(c.c, /FIRMWARE_NAME/)).toBe(0);
    expect(logged(b.c, /M42/)).toBe(0);
    expect(logged(ctx, /M42/)).toBe(0);
    // The board handed each reply out once (its buffer: one session, the gateway's), never twice.
    const answers = sim().replyAnswers.filter((t) => /FIRMWARE_NAME/.test(t));
    expect(answers.join('').match(/FIRMWARE_NAME/g)).toHaveLength(5);
    expect(sim().openSessions).toBe(1);
  });

  it('prints, pauses and answers a message box', async () => {
    const { sim, session, ctx } = await rig(null);
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.cmd.start, { path: '0:/gcodes/bracket.gcode' });
    await until(() => ['processing', 'busy'].includes(String(status(session))));
    expect(session.store.getState().model?.job.file?.fileName).toBe('0:/gcodes/bracket.gcode');
    await ctx.commands.run(session.cmd.pause, undefined);
    await until(() => status(session) === 'paused');
    const seq = sim().printer.raiseMessageBox(3);
    await until(() => session.store.getState().model?.state.messageBox?.seq === seq);
    const box = session.store.getState().model?.state.messageBox;
    if (!box) throw new Error('no box');
    await ctx.commands.run(session.cmd.answer, { box });
    expect(sim().printer.answers).toEqual([{ seq, cancelled: false, value: null }]);
    await until(() => session.store.getState().model?.state.messageBox === null);
    await ctx.commands.run(session.cmd.resume, undefined);
    await until(() => status(session) === 'processing');
  }, 30_000);

  it('files: paged listing, file info with a paged thumbnail, move and delete (uploads: standalone-upload.test.ts)', async () => {
    const { sim, session, ctx } = await rig(null);
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    for (let i = 0; i < FILELIST_PAGE + 2; i++)
      sim().printer.fs.write(`0:/gcodes/batch/p${i}.gcode`, 'G28\n');
    const list = await session.loadDir('0:/gcodes/batch');
    expect(list.map((e) => e.name)).toHaveLength(FILELIST_PAGE + 2);
    sim().printer.fs.write('0:/gcodes/new part.gcode', 'G28\n');
    const info = await session.loadFileInfo('0:/gcodes/bracket.gcode');
    const thumb = info.thumbnails[0];
    expect(thumb?.data).toBe(
      (
        sim().printer.fs.fileInfo('0:/gcodes/bracket.gcode', true)?.['thumbnails'] as Array<{ data: string }>
      )[0]?.data,
    );
    await ctx.commands.run(session.cmd.move, {
      from: '0:/gcodes/new part.gcode',
      to: '0:/gcodes/renamed.gcode',
    });
    expect(sim().printer.fs.exists('0:/gcodes/renamed.gcode')).toBe(true);
    await ctx.commands.run(session.cmd.del, { path: '0:/gcodes/renamed.gcode', dir: false });
    expect(sim().printer.fs.exists('0:/gcodes/renamed.gcode')).toBe(false);
    // A failed delete ({"err":1}) is a failed command, shown as such.
    await expect(
      ctx.commands.run(session.cmd.del, { path: '0:/gcodes/none.gcode', dir: false }),
    ).rejects.toThrow(/err 1/);
  });

  it('an expired session (8 s of silence, or the board restarted) is renewed; the page stays online', async () => {
    const { sim, session, ctx } = await rig('rrf-pass-2', 'rrf-pass-2');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    sim().expireSessions();
    await ctx.commands.run(session.cmd.console, { code: 'M115' }).catch(() => undefined);
    await until(() => sim().openSessions === 1 && ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.cmd.console, { code: 'G28' });
    expect(sim().printer.codes).toContain('G28');
  }, 30_000);

  it('a board with no free session (err 2) is shown as such, and joins once one is free', async () => {
    const { sim, session, ctx } = await rig(null);
    // Other clients (Duet Web Control tabs) hold every session of the board.
    const holders: string[] = [];
    const take = async () => {
      const r = await sim().fetch(
        new Request('http://x/rr_connect?sessionKey=yes'),
        '/rr_connect?sessionKey=yes',
      );
      return String(((await r.json()) as { sessionKey: number }).sessionKey);
    };
    // The simulator is made by the gateway on first use: a probe request first.
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    session.stop();
    sim().expireSessions();
    for (let i = 0; i < MAX_SESSIONS; i++) holders.push(await take());
    const again = new DuetSession(ctx);
    cleanups.push(() => again.stop());
    again.start();
    await until(() => /no free session/.test(ctx.snapshot.getState().problem?.message ?? ''));
    expect(ctx.snapshot.getState().link).not.toBe('online');
    await sim().fetch(
      new Request('http://x/rr_disconnect', { headers: { 'X-Session-Key': holders[0] ?? '' } }),
      '/rr_disconnect',
    );
    await until(() => ctx.snapshot.getState().link === 'online', 20_000);
  }, 30_000);

  it('a wrong configured password (err 1) is "needs login"', async () => {
    const { session, ctx } = await rig('rrf-pass-3', 'not-the-password');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'needs-login');
    expect(session.store.getState().needsPassword).toBe(true);
  });

  it('attacks through rr_* are refused by the gateway: the G-code in the query, files, a forged key', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    let sim: RrfSimulator | null = null;
    const usersFile = path.join(t.dir, 'users.json');
    writeJson(usersFile, {
      users: [user('vera', 'viewer', 'pw-vera-1'), user('otto', 'operator', 'pw-otto-1')],
    });
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 'rs', name: 'Duet 2', kind: 'duet', simulated: true, url: null, wsUrl: null, secrets: {} },
        ],
      },
      families: {
        duet: {
          ...duetFamily,
          createSimulator: (o) => (sim = new RrfSimulator({ ...o, password: null, tickMs: 100 })),
        },
      },
      dataDir: t.dir,
      usersFile,
      env: {},
    });
    cleanups.push(gw.close);
    const get = (cookie: string, p: string, init: RequestInit = {}) =>
      consoleFetch(`${gw.url}/machines/rs${p}`, { ...init, headers: { Cookie: cookie, ...init.headers } });
    const g = (code: string) => `/rr_gcode?gcode=${encodeURIComponent(code)}`;
    const vera = await login(gw.url, 'vera', 'pw-vera-1');
    const otto = await login(gw.url, 'otto', 'pw-otto-1');
    expect((await get(vera, '/rr_model?key=state.status&flags=')).status).toBe(200);
    for (const p of [
      g('M25'),
      '/rr_download?name=0%3A%2Fsys%2Fconfig.g',
      '/rr_delete?name=0%3A%2Fgcodes%2Fx.g',
    ])
      expect((await get(vera, p)).status, p).toBe(403);
    for (const p of [
      g('M98 P"evil.g"'),
      g('M25\nM999'),
      g('M112 M999 G1 X10'),
      g('M104 S250'),
      g('M562 P1'),
      g('G1 X100'),
      g('M25M98 P"evil.g"'),
      '/rr_gcode?gcode=M25&GCODE=M98%20P%22evil.g%22',
      '/rr_delete?name=0%3A%2Fgcodes%2Fbracket.gcode',
      '/rr_mkdir?dir=0%3A%2Fsys%2Fx',
      '/rr_download?name=0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g',
    ])
      expect((await get(otto, p)).status, p).toBe(403);
    const upload = await get(otto, '/rr_upload?name=0%3A%2Fsys%2Fconfig.g', {
      method: 'POST',
      body: 'M551 P"x"',
    });
    expect(upload.status).toBe(403);
    // The operator's job control passes, with the gateway's key, not one the browser made up.
    const ok = await get(otto, g('M25'), { headers: { 'X-Session-Key': '12345' } });
    expect(ok.status).toBe(200);
    expect(await ok.json()).toHaveProperty('buff');
    if (!sim) throw new Error('no simulator');
    const rrf: RrfSimulator = sim;
    expect(rrf.printer.codes).toEqual(['M25']);
    expect(rrf.printer.fs.exists('0:/sys/config.g')).toBe(true);
    // The browser's connect is the gateway's: no key in the answer, no second session on the board.
    const c = (await (await get(vera, '/rr_connect?password=&sessionKey=yes')).json()) as Record<
      string,
      unknown
    >;
    expect(c).toMatchObject({ err: 0 });
    expect(c).not.toHaveProperty('sessionKey');
    // A login from the page replaces the gateway's session: the old one is ended, not left to expire.
    await until(() => rrf.openSessions === 1, 3000);
    expect(rrf.requests.filter((r) => r === 'GET /rr_disconnect')).toHaveLength(1);
  });

  it('attack: a viewer asks rr_reply (plain, ?seq=, any spelling, over the read socket) for an operator’s reply: the board is never asked for it by the viewer, the viewer gets nothing of it, the operator gets it', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    let sim: RrfSimulator | null = null;
    const usersFile = path.join(t.dir, 'users.json');
    writeJson(usersFile, {
      users: [user('vera', 'viewer', 'pw-vera-1'), user('sue', 'supervisor', 'pw-sue-1')],
    });
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 'rs', name: 'Duet 2', kind: 'duet', simulated: true, url: null, wsUrl: null, secrets: {} },
        ],
      },
      families: {
        duet: {
          ...duetFamily,
          createSimulator: (o) => (sim = new RrfSimulator({ ...o, password: null, tickMs: 100 })),
        },
      },
      dataDir: t.dir,
      usersFile,
      env: {},
    });
    cleanups.push(gw.close);
    const get = (cookie: string, p: string, init: RequestInit = {}) =>
      consoleFetch(`${gw.url}/machines/rs${p}`, { ...init, headers: { Cookie: cookie, ...init.headers } });
    const vera = await login(gw.url, 'vera', 'pw-vera-1');
    const sue = await login(gw.url, 'sue', 'pw-sue-1');
    // The session is open, the board idle: the reply number read once.
    expect((await get(vera, '/rr_model?key=seqs&flags=d99vno')).status).toBe(200);
    if (!sim) throw new Error('no simulator');
    const rrf: RrfSimulator = sim;
    const sent = await get(sue, `/rr_gcode?gcode=${encodeURIComponent('M587 S"shop" P"wifi-pass-9"\nM115')}`);
    expect(sent.status).toBe(200);
    const { replyTicket } = (await sent.json()) as { replyTicket: string };
    expect(replyTicket).toMatch(/^[0-9a-f-]{36}$/);
    const boardAsked = () => rrf.requests.filter((r) => r === 'GET /rr_reply').length;
    const askedBefore = boardAsked();
    const texts: string[] = [];
    for (const p of [
      '/rr_reply',
      '/rr_reply?seq=1',
      '/rr_reply?seq=2',
      '/RR_REPLY',
      '//rr_reply/',
      '/rr_%72eply',
      '/rr_reply?after=0',
      `/rr_reply?ticket=${'0'.repeat(8)}-0000-0000-0000-${'0'.repeat(12)}`,
    ]) {
      const r = await get(vera, p, { headers: { 'X-Session-Key': '1' } });
      texts.push(`${p} ${r.status} ${await r.text()}`);
    }
    // Over the page's read socket too.
    const w = await openWs(`ws://${gw.host}/api/reads`, { Cookie: vera }, false);
    cleanups.push(() => w.close());
    for (const [id, url] of [
      [1, '/machines/rs/rr_reply'],
      [2, '/machines/rs/rr_reply?seq=3'],
    ] as const) {
      w.ws.send(JSON.stringify({ id, url }));
      texts.push(await w.next());
    }
    for (const text of texts) expect(text).not.toMatch(/FIRMWARE_NAME|M587|wifi-pass/);
    // The board's reply buffer was read by the gateway only (once, for the code's reply).
    expect(boardAsked() - askedBefore).toBeLessThanOrEqual(1);
    expect(rrf.replyAnswers.filter((a) => /FIRMWARE_NAME/.test(a))).toHaveLength(1);
    // The supervisor who sent it gets it, once.
    const mine = (await (await get(sue, `/rr_reply?ticket=${replyTicket}`)).json()) as {
      replies: Record<string, string>;
    };
    expect(mine.replies[replyTicket]).toMatch(/FIRMWARE_NAME/);
    const again = (await (await get(sue, `/rr_reply?ticket=${replyTicket}`)).json()) as {
      replies: Record<string, string>;
    };
    expect(again.replies).toEqual({});
  });
});
