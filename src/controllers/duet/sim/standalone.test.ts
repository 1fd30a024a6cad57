import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { crc32Hex } from '../crc32';
import type { JsonObject } from '../patch';
import { FILELIST_PAGE, MAX_SESSIONS, RrfSimulator, SESSION_TIMEOUT_MS } from './standalone';

let sim: RrfSimulator;

beforeEach(() => {
  vi.useFakeTimers();
  vi.setSystemTime(1_700_000_000_000);
  sim = new RrfSimulator({ id: 'r', name: 'rrf-sim', now: () => Date.now(), tickMs: 250 });
});
afterEach(() => {
  sim.dispose();
  vi.useRealTimers();
});

const req = (method: string, path: string, key: string | null, body?: BodyInit) =>
  sim.fetch(
    new Request(`http://x/machines/r${path}`, {
      method,
      body,
      headers: key !== null ? { 'X-Session-Key': key } : {},
    }),
    path,
  );

async function json(method: string, path: string, key: string | null, body?: BodyInit): Promise<JsonObject> {
  const r = await req(method, path, key, body);
  expect(r.status, `${method} ${path}`).toBe(200);
  return (await r.json()) as JsonObject;
}

async function connect(password = ''): Promise<string> {
  const a = await json(
    'GET',
    `/rr_connect?password=${password}&time=2026-11-28T10:00:00&sessionKey=yes`,
    null,
  );
  expect(a).toMatchObject({ err: 0, sessionTimeout: 8000, apiLevel: 2 });
  expect(a['isEmulated']).toBeUndefined();
  expect(typeof a['sessionKey']).toBe('number');
  return String(a['sessionKey']);
}

describe('RrfSimulator (standalone rr_* API)', () => {
  it('gives a key only with sessionKey=yes, refuses a bad password with err 1', async () => {
    const plain = await json('GET', '/rr_connect?password=&time=2026-11-28T10:00:00', null);
    expect(plain['err']).toBe(0);
    expect(plain['sessionKey']).toBeUndefined();
    sim.password = 'secret';
    expect(await json('GET', '/rr_connect?password=wrong&sessionKey=yes', null)).toEqual({ err: 1 });
    await connect('secret');
  });

  it('answers 401 without a key, with an unknown key, and after 8 s of silence', async () => {
    const key = await connect();
    expect((await req('GET', '/rr_model?key=seqs&flags=', null)).status).toBe(401);
    expect((await req('GET', '/rr_model?key=seqs&flags=', '12345')).status).toBe(401);
    vi.advanceTimersByTime(SESSION_TIMEOUT_MS - 1000);
    expect((await req('GET', '/rr_model?key=seqs&flags=', key)).status).toBe(200); // kept alive
    vi.advanceTimersByTime(SESSION_TIMEOUT_MS + 1);
    expect((await req('GET', '/rr_model?key=seqs&flags=', key)).status).toBe(401);
  });

  it('has at most 8 sessions: the ninth gets err 2 until one disconnects or expires', async () => {
    const keys: string[] = [];
    for (let i = 0; i < MAX_SESSIONS; i++) keys.push(await connect());
    expect(await json('GET', '/rr_connect?password=&sessionKey=yes', null)).toEqual({ err: 2 });
    expect(await json('GET', '/rr_disconnect', keys[0] ?? '')).toEqual({ err: 0 });
    await connect();
    expect(await json('GET', '/rr_connect?password=&sessionKey=yes', null)).toEqual({ err: 2 });
    vi.advanceTimersByTime(SESSION_TIMEOUT_MS + 1);
    await connect();
  });

  it('wraps the model as {key, flags, result}: live parts with f, one key, seqs that move', async () => {
    const key = await connect();
    const full = await json('GET', '/rr_model?key=&flags=d99vno', key);
    expect(full).toMatchObject({ key: '', flags: 'd99vno' });
    const result = full['result'] as JsonObject;
    expect(Object.keys(result)).toEqual(expect.arrayContaining(['state', 'job', 'heat', 'volumes', 'seqs']));
    for (const dsfOnly of ['messages', 'plugins', 'sbc']) expect(result[dsfOnly]).toBeUndefined();
    const live = (await json('GET', '/rr_model?flags=d99fn', key))['result'] as JsonObject;
    expect(live['state']).toBeDefined();
    expect(live['volumes']).toBeUndefined();
    const seqs0 = (await json('GET', '/rr_model?key=seqs&flags=d99vno', key))['result'] as JsonObject;
    const vol = await json('GET', '/rr_model?key=volumes&flags=d99vno', key);
    expect(Array.isArray(vol['result'])).toBe(true);
    // An upload changes the card's free space: seqs.volumes moves, seqs.heat does not.
    const data = new TextEncoder().encode('G28\n');
    await json(
      'POST',
      `/rr_upload?name=${encodeURIComponent('0:/gcodes/x.g')}&crc32=${crc32Hex(data)}`,
      key,
      data,
    );
    const seqs1 = (await json('GET', '/rr_model?key=seqs&flags=d99vno', key))['result'] as JsonObject;
    expect(seqs1['heat']).toBe(seqs0['heat']);
    expect(await json('GET', '/rr_model?key=state.status&flags=', key)).toMatchObject({ result: 'idle' });
  });

  it('runs G-code: {"buff":n}, the reply by rr_reply once seqs.reply moved', async () => {
    const key = await connect();
    await connect();
    const seq = async (k: string) =>
      ((await json('GET', '/rr_model?key=seqs&flags=', k))['result'] as JsonObject)['reply'];
    const before = await seq(key);
    expect(await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, key)).toEqual({
      buff: expect.any(Number) as number,
    });
    expect(await seq(key)).toBe(Number(before) + 1);
    const text = await (await req('GET', '/rr_reply', key)).text();
    expect(text).toMatch(/FIRMWARE_NAME/);
    expect(sim.printer.codes).toContain('M115');
  });

  it('keeps ONE reply buffer for every session, cleared after as many fetches as there are sessions (HttpResponder.cpp)', async () => {
    const a = await connect();
    const b = await connect();
    const reply = async (k: string) => (await req('GET', '/rr_reply', k)).text();
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, a);
    // Two sessions: two fetches, by anyone (the same session twice counts twice), then it is gone.
    expect(await reply(a)).toMatch(/FIRMWARE_NAME/);
    expect(await reply(a)).toMatch(/FIRMWARE_NAME/);
    expect(await reply(b)).toBe('');
    // Replies not fetched are appended (the buffer is the board's, not a code's).
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, a);
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, b);
    expect((await reply(b)).match(/FIRMWARE_NAME/g)).toHaveLength(2);
    // One session left: its first fetch takes the reply, whoever sent the code.
    await json('GET', '/rr_disconnect', b);
    await reply(a);
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, a);
    const c = await connect();
    await reply(c);
    // c and a: c served once; a's fetch is the second of two: cleared.
    expect(await reply(a)).toMatch(/FIRMWARE_NAME/);
    expect(await reply(c)).toBe('');
    // A session that times out counts as served (CheckSessions): a's one fetch of two is enough.
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M115')}`, a);
    expect(await reply(a)).toMatch(/FIRMWARE_NAME/);
    vi.advanceTimersByTime(SESSION_TIMEOUT_MS / 2);
    await req('GET', '/rr_model?key=seqs&flags=', a);
    vi.advanceTimersByTime(SESSION_TIMEOUT_MS / 2 + 1000);
    expect(sim.openSessions).toBe(1);
    expect(await reply(a)).toBe('');
  });

  it('refuses an upload whose crc32 does not match with {"err":1}, then rr_upload GET says 1', async () => {
    const key = await connect();
    const data = new TextEncoder().encode('G1 X10\n');
    expect(await json('POST', '/rr_upload?name=0:/gcodes/bad.g&crc32=deadbeef', key, data)).toEqual({
      err: 1,
    });
    expect(await json('GET', '/rr_upload', key)).toEqual({ err: 1 });
    expect(sim.printer.fs.exists('0:/gcodes/bad.g')).toBe(false);
    expect(await json('POST', `/rr_upload?name=0:/gcodes/ok.g&crc32=${crc32Hex(data)}`, key, data)).toEqual({
      err: 0,
    });
    expect(await (await req('GET', '/rr_download?name=0:/gcodes/ok.g', key)).text()).toBe('G1 X10\n');
    expect((await req('GET', '/rr_download?name=0:/gcodes/none.g', key)).status).toBe(404);
  });

  it('pages rr_filelist with first/next, and manages files', async () => {
    const key = await connect();
    for (let i = 0; i < FILELIST_PAGE + 3; i++) sim.printer.fs.write(`0:/gcodes/many/f${i}.g`, 'G28\n');
    const p1 = await json('GET', '/rr_filelist?dir=0:/gcodes/many&first=0', key);
    expect((p1['files'] as unknown[]).length).toBe(FILELIST_PAGE);
    expect(p1['next']).toBe(FILELIST_PAGE);
    const p2 = await json('GET', `/rr_filelist?dir=0:/gcodes/many&first=${FILELIST_PAGE}`, key);
    expect((p2['files'] as unknown[]).length).toBe(3);
    expect(p2['next']).toBe(0);
    expect(await json('GET', '/rr_filelist?dir=0:/nope', key)).toMatchObject({ err: 2 });
    expect(await json('GET', '/rr_mkdir?dir=0:/gcodes/new', key)).toEqual({ err: 0 });
    expect(await json('GET', '/rr_move?old=0:/gcodes/many/f0.g&new=0:/gcodes/new/f0.g', key)).toEqual({
      err: 0,
    });
    expect(await json('GET', '/rr_move?old=0:/gcodes/many/f1.g&new=0:/gcodes/new/f0.g', key)).toEqual({
      err: 1,
    });
    expect(
      await json('GET', '/rr_move?old=0:/gcodes/many/f1.g&new=0:/gcodes/new/f0.g&deleteexisting=yes', key),
    ).toEqual({ err: 0 });
    expect(await json('GET', '/rr_delete?name=0:/gcodes/new', key)).toEqual({ err: 1 }); // not empty
    expect(await json('GET', '/rr_delete?name=0:/gcodes/new&recursive=yes', key)).toEqual({ err: 0 });
  });

  it('gives file info without thumbnail data, and the thumbnail by pages', async () => {
    const key = await connect();
    const info = await json('GET', `/rr_fileinfo?name=${encodeURIComponent('0:/gcodes/bracket.gcode')}`, key);
    expect(info['err']).toBe(0);
    const thumbs = info['thumbnails'] as JsonObject[];
    expect(thumbs.length).toBeGreaterThan(0);
    const t = thumbs[0] as JsonObject;
    expect(t['data']).toBeUndefined();
    let offset = Number(t['offset']);
    let data = '';
    for (let i = 0; i < 100 && offset !== 0; i++) {
      const page = await json('GET', `/rr_thumbnail?name=0:/gcodes/bracket.gcode&offset=${offset}`, key);
      expect(page['err']).toBe(0);
      data += String(page['data']);
      offset = Number(page['next']);
    }
    expect(offset).toBe(0);
    const whole = sim.printer.fs.fileInfo('0:/gcodes/bracket.gcode', true)?.['thumbnails'] as JsonObject[];
    expect(data).toBe(whole[0]?.['data']);
    expect(await json('GET', '/rr_fileinfo?name=0:/gcodes/none.g', key)).toEqual({ err: 1 });
  });

  it('prints, pauses and raises a message box on the shared printer model', async () => {
    const key = await connect();
    await json('GET', `/rr_gcode?gcode=${encodeURIComponent('M32 "0:/gcodes/bracket.gcode"')}`, key);
    vi.advanceTimersByTime(1000);
    const status = async () => (await json('GET', '/rr_model?key=state.status&flags=', key))['result'];
    expect(await status()).toMatch(/processing|simulating|busy/);
    await json('GET', '/rr_gcode?gcode=M25', key);
    vi.advanceTimersByTime(3000);
    expect(await status()).toMatch(/paus/);
    sim.printer.raiseMessageBox(3);
    const box = (await json('GET', '/rr_model?flags=d99fn', key))['result'] as JsonObject;
    expect((box['state'] as JsonObject)['messageBox']).toMatchObject({ mode: 3 });
  });
});
