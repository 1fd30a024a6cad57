import { readFileSync } from 'node:fs';
import { describe, expect, it } from 'vitest';
import { LinkError } from '../../fleet/errors';
import {
  classifyMachineType,
  devNameSchema,
  discoveryReplySchema,
  discoveryResponseSchema,
  dotModeSchema,
  flameSensitivityWords,
  frameSchema,
  laserPowerInfoSchema,
  laserPowerTypeSchema,
  listSchema,
  macSchema,
  machineTypeSchema,
  offsetSchema,
  parseFrameText,
  parseXtoolError,
  peripheryStatusSchema,
  pingSchema,
  progressSchema,
  resultSchema,
  upgradeReplySchema,
  versionSchema,
  workingStaSchema,
} from './wire';

const FIXTURES = new URL('../../../tests/fixtures/xtool/', import.meta.url);
const text = (name: string) => readFileSync(new URL(name, FIXTURES), 'utf8');
const json = (name: string): unknown => JSON.parse(text(name));
const http = (name: string) => json(`d-series/http/${name}`);

describe('D-series HTTP fixtures', () => {
  it('parses /ping and plain results', () => {
    expect(pingSchema.parse(http('GET_ping.json')).result).toBe('ok');
    expect(resultSchema.parse(http('result_ok.json')).result).toBe('ok');
    expect(resultSchema.parse(http('result_fail.json')).result).toBe('fail');
  });

  it('parses /progress, and the same with numbers sent as strings', () => {
    expect(progressSchema.parse(http('GET_progress.json'))).toEqual({
      progress: 100,
      working: 56197,
      line: 0,
    });
    expect(progressSchema.parse({ progress: '0', working: '1200', line: ' 7 ' })).toEqual({
      progress: 0,
      working: 1200,
      line: 7,
    });
  });

  it('rejects a /progress whose numbers are not numbers, naming the field', () => {
    const r = progressSchema.safeParse({ progress: 'lots', working: 1 });
    expect(r.success).toBe(false);
    expect(r.error?.issues[0]?.path).toEqual(['progress']);
    expect(progressSchema.safeParse({ progress: '', working: 1 }).success).toBe(false);
  });

  it('parses identity endpoints', () => {
    expect(machineTypeSchema.parse(http('GET_getmachinetype.json')).type).toBe('xTool D1Pro');
    expect(laserPowerTypeSchema.parse(http('GET_getlaserpowertype.json')).power).toBe(10);
    const info = laserPowerInfoSchema.parse(http('GET_getlaserpowerinfo.json'));
    expect([info.type, info.power]).toEqual([0, 10]);
    expect(macSchema.parse(http('GET_system_action=mac.json')).mac).toBe('XX:XX:XX:XX:XX:XX');
    const v = versionSchema.parse(http('GET_system_action=version.json'));
    expect([v.sn, v.version]).toEqual(['XXXXXXXXXXXXXXX', 'V40.31.006.01 B2']);
    expect(devNameSchema.parse(http('GET_system_action=get_dev_name.json')).name).toBe('My xTool D1 Pro');
  });

  it('parses settings: offset, dot mode, periphery status', () => {
    expect(offsetSchema.parse(http('GET_system_action=offset.json'))).toMatchObject({ x: 0, y: 0 });
    expect(dotModeSchema.parse(http('GET_system_action=dotMode.json')).dotMode).toBe(0);
    const p = peripheryStatusSchema.parse(http('GET_peripherystatus.json'));
    expect(p).toMatchObject({
      status: 'normal',
      sdCard: true,
      limitStopFlag: true,
      tiltStopFlag: true,
      movingStopFlag: true,
      tiltThreshold: 15,
      movingThreshold: 40,
      flameAlarmMode: 3,
      flameAlarmSensitivity: 1,
    });
    expect(flameSensitivityWords(p.flameAlarmSensitivity ?? 0)).toBe('high');
  });

  it('accepts the short /peripherystatus of older firmware', () => {
    const p = peripheryStatusSchema.parse({ result: 'ok', status: 'normal', sdCard: '0' });
    expect(p.sdCard).toBe(false);
    expect(p.limitStopFlag).toBeUndefined();
    expect(p.flameAlarmSensitivity).toBeUndefined();
  });

  it('maps get_working_sta codes, unknown ones explicitly', () => {
    expect(workingStaSchema.parse(http('GET_system_action=get_working_sta.json'))).toEqual({
      code: 'idle',
      raw: '0',
    });
    expect(workingStaSchema.parse({ result: 'ok', working: '1' }).code).toBe('api');
    expect(workingStaSchema.parse({ result: 'ok', working: 2 }).code).toBe('button');
    expect(workingStaSchema.parse({ result: 'ok', working: '7' })).toEqual({ code: 'unknown', raw: '7' });
  });

  it('parses /list, also empty or single-entry answers', () => {
    expect(listSchema.parse(http('GET_list.json')).name).toEqual(['/frame.gcode', '/tmp.gcode']);
    expect(listSchema.parse({ type: 'dir' }).name).toEqual([]);
    expect(listSchema.parse({ type: 'dir', name: '/a.gcode' }).name).toEqual(['/a.gcode']);
  });

  it('parses the plain-text firmware upgrade answers', () => {
    expect(upgradeReplySchema.parse(text('d-series/http/POST_upgrade_response_ok.txt'))).toBe('OK');
    expect(upgradeReplySchema.parse(text('d-series/http/POST_upgrade_response_fail.txt'))).toBe('FAIL');
    expect(upgradeReplySchema.safeParse('<html>').success).toBe(false);
  });
});

describe('vendor error parser', () => {
  it('turns fail with HTTP 200 into a vendor error', () => {
    const e = parseXtoolError(200, http('result_fail.json'), '');
    expect(e).toBeInstanceOf(LinkError);
    expect(e?.kind).toBe('vendor');
    expect(e?.vendorMessage).toBe('fail');
  });
  it('explains "no file" (unknown path) and passes ok and result-less bodies', () => {
    expect(parseXtoolError(200, { result: 'no file' }, '')?.message).toMatch(/does not know this path/);
    expect(parseXtoolError(200, http('result_ok.json'), '')).toBeNull();
    expect(parseXtoolError(200, http('GET_progress.json'), '')).toBeNull();
    expect(parseXtoolError(200, http('GET_list.json'), '')).toBeNull();
  });
  it('reports what other models answer', () => {
    const other = JSON.parse(text('other-models/unknown-path_response_invalid_request.txt')) as unknown;
    expect(parseXtoolError(200, other, '')?.vendorMessage).toBe('invalid request');
    expect(
      parseXtoolError(200, json('other-models/apparel-printer_GET_peripherystatus.json'), '')?.vendorMessage,
    ).toBe('failed');
  });
});

describe('WebSocket frames', () => {
  const table = json('d-series/ws-frames.json') as {
    frames: Array<{ frame: string; status: string; alt_spellings?: string[] }>;
  };

  it('knows every frame of the table, with a terminator, in every spelling', () => {
    for (const row of table.frames) {
      for (const spelling of [row.frame, ...(row.alt_spellings ?? [])]) {
        for (const term of ['\n', '\0', '\r\n', '']) {
          const f = frameSchema.parse(spelling + term);
          expect(f.kind, `${JSON.stringify(spelling + term)}`).not.toBe('unknown');
          expect(f.raw).toBe(spelling);
        }
      }
    }
  });

  it('maps frames to states, stops, errors and sensors', () => {
    expect(parseFrameText('ok:WORKING_ONLINE_READY\n')).toEqual({
      kind: 'state',
      state: 'job-loaded',
      raw: 'ok:WORKING_ONLINE_READY',
    });
    expect(parseFrameText('ok:WORKING_OFFLINE\n')).toMatchObject({ state: 'running-offline' });
    expect(parseFrameText('ok:PAUSING\0')).toMatchObject({ state: 'paused' });
    expect(parseFrameText('WORK_STOPED\n').kind).toBe('stopped');
    expect(parseFrameText('ok:ERROR\n').kind).toBe('error');
    expect(parseFrameText('err:flameCheck\n')).toMatchObject({ kind: 'sensor', sensor: 'flame' });
    expect(parseFrameText('err:tiltCheck\n')).toMatchObject({ kind: 'sensor', sensor: 'tilt' });
    expect(parseFrameText('ok:SOMETHING_NEW\n')).toEqual({ kind: 'unknown', raw: 'ok:SOMETHING_NEW' });
  });
});

describe('models and discovery', () => {
  it('tells D-series from other xTool families', () => {
    expect(classifyMachineType('xTool D1Pro')).toBe('d-series');
    expect(classifyMachineType('xTool D1 Pro 2.0')).toBe('d-series');
    expect(classifyMachineType('xTool S1')).toBe('unsupported');
    expect(classifyMachineType('xTool F1')).toBe('unsupported');
    const metalfab = json('other-models/metalfab_GET_system_action=version_v2.json') as {
      machine_name: string;
    };
    expect(classifyMachineType(metalfab.machine_name)).toBe('unsupported');
  });

  it('parses device discovery replies', () => {
    const d1 = discoveryReplySchema.parse(json('discovery/udp-reply-d1pro.json'));
    expect(d1).toMatchObject({
      requestId: 123456,
      ip: '192.168.178.229',
      name: 'xTool D1 Pro',
      via: 'unknown',
    });
    const s1 = discoveryReplySchema.parse({ ...(json('discovery/udp-reply-s1.json') as object), via: 'tcp' });
    expect(s1).toMatchObject({ name: '', version: 'V40.32.013.2224.01', via: 'tcp' });
    expect(discoveryReplySchema.safeParse(json('discovery/udp-request-minimal.json')).success).toBe(false);
  });

  it('parses the gateway discovery answer', () => {
    const r = discoveryResponseSchema.parse({
      replies: [{ ...(json('discovery/udp-reply-d1pro.json') as object), via: 'udp' }],
      broadcast: '127.0.0.1',
    });
    expect(r.replies[0]?.via).toBe('udp');
    expect(discoveryResponseSchema.safeParse({ replies: [{ name: 'x' }] }).success).toBe(false);
  });
});
