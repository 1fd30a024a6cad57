import { describe, expect, it } from 'vitest';
import type { UpstreamAnswer, UpstreamRequest } from '../../fleet/contract';
import { duetFamily } from './family';
import { duetHeldSession, duetHeldSessionFor, rrfTime, type DuetApiState } from './gateway';
import { duetSharing, rrfWatch } from './sharing';

/**
 * The gateway's probe (issue 20): `rr_connect` first, as Duet Web Control does; a standalone board
 * answers with `err` and no `isEmulated`; DSF ≥ 3.5 answers `isEmulated: true`, older DSF 404.
 */

const ans = (status: number, body: unknown = ''): UpstreamAnswer => ({
  status,
  headers: { 'content-type': 'application/json' },
  body: typeof body === 'string' ? body : JSON.stringify(body),
});

function upstreamOf(answers: Record<string, UpstreamAnswer>) {
  const sent: Array<{ method: string; path: string; headers?: Record<string, string> }> = [];
  const upstream: UpstreamRequest = (method, path, headers) => {
    sent.push({ method, path, headers });
    const route = path.split('?')[0] ?? '';
    return Promise.resolve(answers[route] ?? ans(404));
  };
  return { sent, upstream };
}

const RRF_OK = {
  err: 0,
  sessionTimeout: 8000,
  boardType: 'duetwifi102',
  apiLevel: 2,
  sessionKey: 3735928559,
};

describe('duet held session: standalone or DSF', () => {
  it('a standalone board: rr_connect with sessionKey=yes, the key held, the answer without it', async () => {
    const hooks = duetHeldSessionFor({ api: null });
    const { sent, upstream } = upstreamOf({ '/rr_connect': ans(200, RRF_OK) });
    const r = await hooks.open(upstream, { password: 'p w' });
    expect(r).toMatchObject({ ok: true, key: '3735928559' });
    expect(r.answer.body).not.toContain('3735928559');
    expect(JSON.parse(r.answer.body)).toMatchObject({ err: 0, apiLevel: 2, sessionTimeout: 8000 });
    const q = new URLSearchParams((sent[0]?.path ?? '').split('?')[1]);
    expect([q.get('password'), q.get('sessionKey')]).toEqual(['p w', 'yes']);
    expect(q.get('time')).toMatch(/^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d$/);
    expect(sent).toHaveLength(1); // no /machine/connect
    // From now on: the rr_* keep-alive, rr_disconnect, 401 means expired.
    expect(hooks.keepAlive?.path).toMatch(/^\/rr_model\?key=seqs/);
    expect(hooks.keepAlive?.everyMs).toBeLessThan(8000);
    expect(hooks.isExpired(401)).toBe(true);
    const req = { headers: { 'X-SESSION-KEY': 'forged' }, query: new URLSearchParams() };
    hooks.apply(req, '3735928559');
    expect(req.headers).toEqual({ 'x-session-key': '3735928559' });
    await hooks.close?.(upstream, '3735928559');
    expect(sent.at(-1)).toMatchObject({ path: '/rr_disconnect', headers: { 'X-Session-Key': '3735928559' } });
  });

  it("err 1 (bad password) is a 403 and err 2 (no free session) a 503, with the board's body", async () => {
    const bad = await duetHeldSessionFor({ api: null }).open(
      upstreamOf({ '/rr_connect': ans(200, { err: 1 }) }).upstream,
      {
        password: 'x',
      },
    );
    expect(bad).toMatchObject({ ok: false, answer: { status: 403, body: '{"err":1}' } });
    const busy = await duetHeldSessionFor({ api: null }).open(
      upstreamOf({ '/rr_connect': ans(200, { err: 2 }) }).upstream,
      undefined,
    );
    expect(busy).toMatchObject({ ok: false, answer: { status: 503, body: '{"err":2}' } });
  });

  it('DSF emulating rr_* (isEmulated: true): its emulated session is closed, DSF is used', async () => {
    const hooks = duetHeldSessionFor({ api: null });
    const { sent, upstream } = upstreamOf({
      '/rr_connect': ans(200, { ...RRF_OK, sessionKey: 77, isEmulated: true }),
      '/machine/connect': ans(200, { sessionKey: 'guid-1' }),
    });
    const r = await hooks.open(upstream, undefined);
    expect(r).toMatchObject({ ok: true, key: 'guid-1' });
    expect(sent.map((s) => s.path.split('?')[0])).toEqual([
      '/rr_connect',
      '/rr_disconnect',
      '/machine/connect',
    ]);
    expect(sent[1]?.headers).toEqual({ 'X-Session-Key': '77' });
    expect(hooks.keepAlive?.path).toBe('/machine/noop');
    expect(hooks.isExpired(401, { method: 'GET', path: '/machine/model' })).toBe(false);
    expect(hooks.isExpired(403)).toBe(true);
    // Learned: the next session is DSF's at once.
    await hooks.open(upstream, undefined);
    expect(sent.map((s) => s.path.split('?')[0]).slice(3)).toEqual(['/machine/connect']);
  });

  it('older DSF (404 on rr_connect) is DSF; "api": "dsf" never probes; "standalone" never falls back', async () => {
    const dsf = upstreamOf({ '/machine/connect': ans(200, { sessionKey: 'g' }) });
    expect(await duetHeldSessionFor({ api: null }).open(dsf.upstream, undefined)).toMatchObject({
      ok: true,
      key: 'g',
    });
    const forced = upstreamOf({
      '/rr_connect': ans(200, RRF_OK),
      '/machine/connect': ans(200, { sessionKey: 'g' }),
    });
    await duetHeldSessionFor({ api: 'dsf' }).open(forced.upstream, undefined);
    expect(forced.sent.map((s) => s.path.split('?')[0])).toEqual(['/machine/connect']);
    const gone = upstreamOf({ '/machine/connect': ans(200, { sessionKey: 'g' }) });
    const r = await duetHeldSessionFor({ api: 'standalone' }).open(gone.upstream, undefined);
    expect(r).toMatchObject({ ok: false, answer: { status: 404 } });
    expect(gone.sent.map((s) => s.path.split('?')[0])).toEqual(['/rr_connect']);
  });

  it("intercepts both APIs' connect and disconnect, whatever the spelling", () => {
    const i = (path: string, q = '') =>
      duetHeldSession.intercept({ method: 'GET', path, query: new URLSearchParams(q) });
    expect(i('/rr_connect', 'password=x&sessionKey=yes')).toEqual({
      kind: 'open',
      credentials: { password: 'x' },
    });
    expect(i('/RR_Connect')).toEqual({ kind: 'open' });
    expect(i('/rr_disconnect')).toEqual({ kind: 'close' });
    expect(i('/machine/connect')).toEqual({ kind: 'open' });
    expect(i('/rr_model')).toBeNull();
  });

  it('sends the local time without a zone', () => {
    expect(rrfTime(new Date(2026, 10, 28, 9, 5, 7))).toBe('2026-11-28T09:05:07');
  });

  it("one machine's sharing follows what its session learned: few reads, no sockets, the rr_model watch", async () => {
    const h = duetFamily.gateway?.forMachine?.({ id: 'm1' });
    if (!h?.session || !h.sharing) throw new Error('no per-machine hints');
    // Not known yet: DSF's.
    expect(h.sharing.maxConcurrentReads).toBe(duetSharing.maxConcurrentReads);
    // The watch's first read is DSF's model poll, without the socket: it opens the session, whose
    // probe learns the API, and the watch reads again with that API's poll.
    expect(h.sharing.watch?.poll).toBe(duetSharing.watch?.poll);
    expect(h.sharing.watch?.stream).toBeUndefined();
    await h.session.open(upstreamOf({ '/rr_connect': ans(200, RRF_OK) }).upstream, undefined);
    expect(h.sharing.maxConcurrentReads).toBe(2);
    expect(h.sharing.keepAlive).toBe(false);
    expect(h.sharing.streams).toEqual([]);
    expect(h.sharing.watch?.poll).toBe(rrfWatch.poll);
    expect(h.sharing.watch?.stream).toBeUndefined();
    expect(h.sharing.shareRead?.('/rr_model', new URLSearchParams('key=&flags=d99fn'))).toBe(1000);
    expect(h.sharing.shareRead?.('/rr_gcode', new URLSearchParams('gcode=M25'))).toBeNull();
    // rr_reply is never shared (nor forwarded: the gateway answers it, replies.ts).
    expect(h.sharing.shareRead?.('/rr_reply', new URLSearchParams())).toBeNull();
    expect(h.sharing.shareRead?.('/rr_reply', new URLSearchParams('seq=7'))).toBeNull();
    for (const [method, path, q] of [
      ['GET', '/rr_reply', ''],
      ['GET', '/RR_Reply/', 'seq=7'],
      ['POST', '/rr_reply', ''],
      ['GET', '/rr_gcode', 'gcode=M115'],
    ] as const)
      expect(h.session.intercept({ method, path, query: new URLSearchParams(q) })?.kind, path).toBe('relay');
    // Forced by the machines file: standalone from the start.
    const forced = duetFamily.gateway?.forMachine?.({ id: 'm2', api: 'standalone' });
    expect(forced?.sharing?.watch?.poll).toBe(rrfWatch.poll);
    const dsf = duetFamily.gateway?.forMachine?.({ id: 'm3', api: 'dsf' });
    expect(dsf?.sharing?.watch?.poll).toBe(duetSharing.watch?.poll);
    expect(dsf?.sharing?.watch?.stream).toBe(duetSharing.watch?.stream);
    const state: DuetApiState = { api: null };
    await duetHeldSessionFor(state).open(
      upstreamOf({ '/machine/connect': ans(200, { sessionKey: 'g' }) }).upstream,
      undefined,
    );
    expect(state.api).toBe('dsf');
  });

  it('the watch reads a standalone model: state, job, alarms; bad answers are errors', () => {
    const model = {
      state: { status: 'processing' },
      job: { file: { fileName: '0:/gcodes/a.gcode' } },
      heat: { heaters: [{ state: 'fault' }] },
    };
    const r = rrfWatch.poll?.read(
      200,
      JSON.stringify({ key: '', flags: 'd99vno', result: { ...model, seqs: {} } }),
    );
    expect(r).not.toBeInstanceOf(Error);
    expect(JSON.stringify(r)).toMatch(/a\.gcode/);
    expect(rrfWatch.poll?.read(401, '')).toBeInstanceOf(Error);
    expect(rrfWatch.poll?.read(200, '{"result":[]}')).toBeInstanceOf(Error);
    expect(rrfWatch.poll?.read(200, 'x')).toBeInstanceOf(Error);
  });
});
