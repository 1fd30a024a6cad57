import { readFileSync } from 'node:fs';
import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import { xtoolAccess } from './access';
import { xtoolDeclaration } from './declaration';
import { POLL_BUSY_MS, POLL_IDLE_MS } from './session';
import {
  classifyXtoolFrame,
  readWorkingSta,
  readXtoolFrame,
  xtoolShareRead,
  STATUS_WINDOW_MS,
  xtoolSharing,
  xtoolStatusStream,
  xtoolWatch,
} from './sharing';

const FIXTURES = new URL('../../../tests/fixtures/xtool/d-series/', import.meta.url);
const fixture = (rel: string) => readFileSync(new URL(rel, FIXTURES), 'utf8');

interface FrameRow {
  frame: string;
  alt_spellings?: string[];
}
const FRAMES = (JSON.parse(fixture('ws-frames.json')) as { frames: FrameRow[] }).frames;
const allFrames = FRAMES.flatMap((f) => [f.frame, ...(f.alt_spellings ?? [])]);

/** Path and query as the gateway hands them over (its canonical split). */
function target(raw: string): { path: string; query: URLSearchParams } {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { path: t.path, query: t.query };
}
const share = (raw: string) => {
  const t = target(raw);
  return xtoolShareRead(t.path, t.query);
};

/** Every GET the document lists (and some it does not), with the parameters the console sends. */
const GETS = [
  '/',
  '/ping',
  '/progress',
  '/getmachinetype',
  '/getlaserpowertype',
  '/getlaserpowerinfo',
  '/peripherystatus',
  '/status',
  '/list?dir=/',
  '/system?action=mac',
  '/system?action=version',
  '/system?action=get_working_sta',
  '/system?action=offset',
  '/system?action=dotMode',
  '/system?action=get_dev_name',
  '/system?action=set_dev_name&name=x',
  '/system?action=setLimitStopSwitch&limitStopSwitch=0',
  '/system?action=setTiltStopSwitch&tiltStopSwitch=0',
  '/system?action=setMovingStopSwitch&movingStopSwitch=0',
  '/system?action=setTiltCheckThreshold&tiltCheckThreshold=15',
  '/system?action=setMovingCheckThreshold&movingCheckThreshold=40',
  '/system?action=setFlameAlarmMode&flameAlarmMode=3',
  '/system?action=setFlameAlarmSensitivity&flameAlarmSensitivity=3',
  '/system',
  '/cnc/data?action=pause',
  '/cnc/data?action=resume',
  '/cnc/data?action=stop',
  '/cmd?cmd=M18',
  '/read?file=/tmp.gcode',
  '/delete?file=/tmp.gcode',
  '/updater',
  '/framing',
  '/net?action=connsta',
];

describe('xTool sharing: the declaration', () => {
  it('is what the declaration gives the gateway, beside the socket port', () => {
    expect(xtoolDeclaration.gateway?.sharing).toBe(xtoolSharing);
    expect(xtoolDeclaration.gateway?.defaultWsPort).toBe(8081);
    expect(xtoolSharing.keepAlive).toBe(false);
    expect(xtoolSharing.maxConcurrentReads).toBe(2);
  });
});

describe('xTool sharing: reads', () => {
  it('never shares a GET that acts (every command of the access policy)', () => {
    const commands = GETS.filter((raw) => xtoolAccess({ method: 'GET', ...target(raw) }).command);
    expect(commands.length).toBeGreaterThanOrEqual(17);
    for (const raw of commands) expect(share(raw), raw).toBeNull();
  });

  it('shares the status poll with the busy period, settings and identity for a minute, and nothing else', () => {
    const shared = GETS.filter((raw) => share(raw) !== null);
    expect(shared.sort()).toEqual([
      '/getlaserpowerinfo',
      '/getlaserpowertype',
      '/getmachinetype',
      '/peripherystatus',
      '/progress',
      '/system?action=dotMode',
      '/system?action=get_dev_name',
      '/system?action=get_working_sta',
      '/system?action=mac',
      '/system?action=offset',
      '/system?action=version',
    ]);
    // The identity every tab reads when it opens: one read a minute for all of them.
    for (const raw of [
      '/getmachinetype',
      '/getlaserpowertype',
      '/getlaserpowerinfo',
      '/system?action=version',
      '/system?action=mac',
      '/system?action=get_dev_name',
    ])
      expect(share(raw), raw).toBe(60_000);
    // The liveness check at connect is never answered from another tab's read.
    expect(share('/ping')).toBeNull();
    // The settings: one read a minute for every tab (a settings command drops the kept answer).
    for (const raw of ['/peripherystatus', '/system?action=offset', '/system?action=dotMode'])
      expect(share(raw), raw).toBe(60_000);
    expect(share('/progress')).toBe(STATUS_WINDOW_MS);
    expect(share('/system?action=get_working_sta')).toBe(STATUS_WINDOW_MS);
    expect(POLL_BUSY_MS).toBeLessThanOrEqual(POLL_IDLE_MS);
    // Shorter than the period (which runs from the end of one poll to the start of the next): a
    // page never gets its own last answer back as new, which would hide a fault for a period.
    expect(STATUS_WINDOW_MS).toBeLessThan(POLL_BUSY_MS);
    expect(STATUS_WINDOW_MS).toBeGreaterThan(0);
  });

  it('shares only the exact form the console sends', () => {
    for (const raw of [
      '/progress/',
      '/PROGRESS',
      '/progress?x=1',
      '/system?action=GET_WORKING_STA',
      '/system?action=get_working_sta&name=x',
      '/system?Action=get_working_sta',
    ])
      expect(share(raw), raw).toBeNull();
    // the gateway refuses a repeated parameter; were one to arrive, the firmware might read the other
    const twice = new URLSearchParams('action=get_working_sta&action=set_dev_name');
    expect(xtoolShareRead('/system', twice)).toBeNull();
  });
});

describe('xTool sharing: the :8081 socket', () => {
  it('is the root path the browser opens', () => {
    expect(xtoolStatusStream.matches('/')).toBe(true);
    expect(xtoolStatusStream.matches('/progress')).toBe(false);
    expect(xtoolWatch.stream?.path).toBe('/');
  });

  it('classifies every documented frame: state frames latest and replayed, alarms events', () => {
    expect(allFrames).toContain('WORK_STOPED');
    for (const f of allFrames) {
      const c = classifyXtoolFrame(`${f}\n`);
      if (f.startsWith('err:') || f === 'ok:ERROR') expect(c, f).toEqual({ kind: 'event', replay: false });
      else expect(c, f).toEqual({ kind: 'latest', key: 'state', replay: true });
    }
    expect(classifyXtoolFrame('ok:IDLE\u0000')).toEqual({ kind: 'latest', key: 'state', replay: true });
  });

  it('keeps unknown frames as events (nothing lost)', () => {
    for (const f of ['ok:SOMETHING_NEW', '', 'garbage', '{"a":1}'])
      expect(classifyXtoolFrame(f).kind, f).toBe('event');
  });

  it('takes nothing from a browser', () => {
    for (const f of ['ok:IDLE', 'PING', '1', '']) expect(xtoolStatusStream.fromBrowser?.(f), f).toBeNull();
  });
});

describe('xTool sharing: the watch', () => {
  it('polls the working state every 10 s and keeps the socket', () => {
    // The watch (no viewer) stays at 10 s; a page polls every 3 s, busy or idle (issue 15).
    expect(xtoolWatch.everyMs).toBe(10_000);
    expect(xtoolWatch.everyMs).toBeGreaterThanOrEqual(POLL_IDLE_MS);
    const p = target(xtoolWatch.poll?.path ?? '');
    expect(xtoolAccess({ method: 'GET', ...p })).toMatchObject({ role: 'viewer', command: false });
    expect(xtoolShareRead(p.path, p.query)).toBe(STATUS_WINDOW_MS);
  });

  it('reads the working state fixture and its other values', () => {
    expect(readWorkingSta(200, fixture('http/GET_system_action=get_working_sta.json'))).toEqual({
      state: 'idle',
      alarm: null,
      job: null,
      // the poll's full list: no alarm (it clears a flame the socket raised)
      alarms: [],
    });
    // Running: the answer names no job, so it says nothing of the job (a frame's name is kept).
    expect(readWorkingSta(200, '{"result":"ok","working":"1"}')).toEqual({
      state: 'running',
      alarm: null,
      alarms: [],
    });
    expect(readWorkingSta(200, '{"result":"ok","working":2}')).toMatchObject({ state: 'running' });
    // Paused, as a frame said: "2" cannot tell paused from running, so the pause stays.
    const paused = { state: 'paused', job: 'tmp.gcode', alarm: null } as const;
    expect(readWorkingSta(200, '{"result":"ok","working":"2"}', paused)).toMatchObject({ state: 'paused' });
    expect(readWorkingSta(200, '{"result":"ok","working":"0"}', paused)).toMatchObject({ state: 'idle' });
    expect(readWorkingSta(200, '{"result":"ok","working":"7"}')).toMatchObject({ state: 'unknown' });
  });

  it('turns a refusal, another status and garbage into an Error, never a throw', () => {
    for (const [status, body] of [
      [200, fixture('http/result_fail.json')],
      [200, '{"result":"no file"}'],
      [200, '{"result":"ok"}'],
      [200, '[]'],
      [200, 'not json'],
      [200, ''],
      [500, '{"result":"ok","working":"0"}'],
    ] as const)
      expect(readWorkingSta(status, body), body).toBeInstanceOf(Error);
  });

  it('reads every documented frame: alarms in words, states as the console counts them', () => {
    const read = (f: string) => readXtoolFrame(`${f}\n`);
    // Idle: nothing loaded any more, so no job name is kept.
    expect(read('ok:IDLE')).toEqual({ state: 'idle', job: null });
    // A software-run job is the uploaded /tmp.gcode: its name for the server's job record (issue 33).
    expect(read('ok:WORKING_ONLINE')).toEqual({ state: 'running', job: 'tmp.gcode' });
    expect(read('ok:WORKING_OFFLINE')).toEqual({ state: 'running' });
    expect(read('ok:WORKING_FRAMING')).toEqual({ state: 'running' });
    // loaded, waiting for the button: nothing moves (README, "Activity")
    expect(read('ok:WORKING_ONLINE_READY')).toEqual({ state: 'idle', job: 'tmp.gcode' });
    expect(read('ok:WORKING_FRAME_READY')).toEqual({ state: 'idle' });
    expect(read('ok:PAUSING')).toEqual({ state: 'paused' });
    expect(read('WORK_STOPPED')).toEqual({ state: 'running' });
    expect(read('WORK_STOPED')).toEqual({ state: 'running' });
    expect(read('err:flameCheck')).toEqual({
      state: 'alarm',
      alarm: expect.stringMatching(/^FLAME DETECTED/),
      raise: [
        {
          key: 'xtool-flame',
          severity: 'critical',
          text: expect.stringMatching(/^FLAME DETECTED/),
          blocking: true,
        },
      ],
    });
    expect(read('err:tiltCheck')).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/Tilt sensor/),
    });
    expect(read('err:movingCheck')).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/Movement sensor/),
    });
    expect(read('err:limitCheck')).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/Limit switch/),
    });
    expect(read('ok:ERROR')).toMatchObject({ state: 'alarm', alarm: expect.stringMatching(/ok:ERROR/) });
    // Only a flame is critical; the other sensors and ok:ERROR are warnings.
    for (const f of ['err:tiltCheck', 'err:movingCheck', 'err:limitCheck', 'ok:ERROR'])
      expect(
        read(f)?.raise?.map((a) => a.severity),
        f,
      ).toEqual(['warning']);
    for (const f of allFrames) expect(read(f), f).not.toBeNull();
  });

  it('says nothing for unknown frames and garbage', () => {
    for (const f of ['ok:SOMETHING_NEW', '', '\u0000', 'err:unknownCheck'])
      expect(readXtoolFrame(f), f).toBeNull();
  });
});
