import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import { pruntAccess } from './access';
import { pruntDeclaration } from './declaration';
import {
  classifyPruntFrame,
  pruntFromBrowser,
  PAGE_OPEN_WINDOW_MS,
  pruntShareRead,
  pruntSharing,
  pruntStream,
  pruntUpstreamRate,
  pruntWatch,
  readPruntFrame,
} from './sharing';
import { divisorFor, FLEET_DIVISOR, LIVE_RATES, TICK_MS } from './state';

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const lines = (rel: string) =>
  readFileSync(join(dir, rel), 'utf8')
    .split('\n')
    .filter((l) => l.trim() !== '');
const FLAT = lines('websocket-messages.jsonl');
const MODULE = lines('v2026/websocket-messages.jsonl');
const firstKey = (l: string) => Object.keys(JSON.parse(l) as object)[0];

describe('Prunt sharing: the declaration', () => {
  it('is what the declaration gives the gateway', () => {
    expect(pruntDeclaration.gateway?.sharing).toBe(pruntSharing);
    expect(pruntDeclaration.gateway?.imageAnswer).toBeDefined();
    expect(pruntSharing.keepAlive).toBe(false);
    expect(pruntSharing.maxConcurrentReads).toBe(2);
  });
});

describe('Prunt sharing: reads', () => {
  it('shares only the page-open reads, briefly; every GET is a read (none audited)', () => {
    const gets = [
      '/config/schema',
      '/config/values',
      '/status/schema',
      '/status/values',
      '/uploads/',
      '/uploads/benchy.gcode',
      '/update-check',
      '/update_check',
      '/',
    ];
    const commands = gets.filter(
      (p) => pruntAccess({ method: 'GET', path: p, query: new URLSearchParams() }).command,
    );
    expect(commands).toEqual([]);
    const none = new URLSearchParams();
    const shared = gets.filter((p) => pruntShareRead(p, none) !== null);
    expect(shared).toEqual(['/status/schema', '/update-check', '/update_check']);
    for (const p of shared) expect(pruntShareRead(p, none)).toBe(PAGE_OPEN_WINDOW_MS);
    expect(PAGE_OPEN_WINDOW_MS).toBeLessThanOrEqual(2000);
    // Only in the form the console sends: with any query, not shared.
    expect(pruntShareRead('/status/schema', new URLSearchParams('x=1'))).toBeNull();
    // What follows a command (values after a pause, the configuration after a save): never.
    expect(pruntShareRead('/status/values', none)).toBeNull();
    expect(pruntShareRead('/config/values', none)).toBeNull();
  });
});

describe('Prunt sharing: /websocket/everything', () => {
  it('is the one socket path', () => {
    expect(pruntStream.matches('/websocket/everything')).toBe(true);
    expect(pruntStream.matches('/websocket')).toBe(false);
    expect(pruntWatch.stream?.path).toBe('/websocket/everything');
  });

  it('classifies every fixture frame of both API generations', () => {
    for (const l of [...FLAT, ...MODULE]) {
      const k = firstKey(l);
      const c = classifyPruntFrame(l);
      if (k === 'Server_Start_Time') expect(c, l).toEqual({ kind: 'latest', key: 'start', replay: true });
      else if (k === 'Status' || k === 'Status_Values')
        expect(c, l.slice(0, 40)).toEqual({ kind: 'latest', key: 'status', replay: true });
      else expect(c, l.slice(0, 40)).toEqual({ kind: 'event', replay: false });
    }
    const kinds = new Set([...FLAT, ...MODULE].map(firstKey));
    expect([...kinds].sort()).toEqual([
      'Gcode_Command',
      'Log',
      'Server_Start_Time',
      'Status',
      'Status_Values',
    ]);
  });

  it('finds the kind wherever the key is, and keeps unknown or broken frames as events', () => {
    expect(classifyPruntFrame('{"Startup":"Done","Status_Values":{}}')).toMatchObject({ key: 'status' });
    expect(classifyPruntFrame(' { "Server_Start_Time" : " 1.0" }')).toMatchObject({ key: 'start' });
    for (const f of ['{"Smart_Plug":{}}', 'not json', '', '[1]', '{"Status_Values":'])
      expect(classifyPruntFrame(f), f).toEqual({ kind: 'event', replay: false });
  });

  it("reads the browser's divisor as the rate it wants", () => {
    for (const hz of LIVE_RATES) {
      const d = divisorFor(hz);
      expect(pruntFromBrowser(String(d)), `${hz} Hz`).toEqual({ rateMs: d * TICK_MS });
    }
    expect(pruntFromBrowser(String(FLEET_DIVISOR))).toEqual({ rateMs: 1000 });
    expect(pruntFromBrowser('1')).toEqual({ rateMs: 50 });
    expect(pruntFromBrowser(' 20\n')).toEqual({ rateMs: 1000 });
    expect(pruntFromBrowser('4294967295')).toEqual({ rateMs: 4294967295 * 50 });
  });

  it('drops anything else a browser sends', () => {
    for (const f of [
      '',
      '0',
      '-1',
      '1.5',
      '2e1',
      '0x14',
      '16#14#',
      '2_0',
      'abc',
      '20 20',
      '4294967296',
      '99999999999',
      '{"d":1}',
    ])
      expect(pruntFromBrowser(f), JSON.stringify(f)).toBeNull();
  });

  it('asks Prunt for the divisor of the fastest rate, never a slower one', () => {
    expect(pruntUpstreamRate(1000)).toBe('20');
    expect(pruntUpstreamRate(200)).toBe('4');
    expect(pruntUpstreamRate(50)).toBe('1');
    expect(pruntUpstreamRate(75)).toBe('1');
    expect(pruntUpstreamRate(10)).toBe('1');
    expect(pruntUpstreamRate(0)).toBe('1');
    expect(pruntUpstreamRate(Infinity)).toBe('4294967295');
    expect(pruntUpstreamRate(Number.NaN)).toBe('20');
    for (const hz of LIVE_RATES) {
      const r = pruntFromBrowser(String(divisorFor(hz)));
      expect(r && pruntUpstreamRate(r.rateMs)).toBe(String(divisorFor(hz)));
    }
  });

  it("starts at Prunt's own default: every 20th tick", () => {
    expect(pruntStream.defaultRateMs).toBe(1000);
    expect(pruntUpstreamRate(pruntStream.defaultRateMs ?? 0)).toBe('20');
  });
});

describe('Prunt sharing: the watch', () => {
  it('reads the module API ticks: a print, then a server exception', () => {
    const ticks = MODULE.filter((l) => firstKey(l) === 'Status_Values').map(readPruntFrame);
    // Startup "Waiting", then "Done" with uploads/benchy.gcode at line 18342, then a recoverable exception
    expect(ticks[0]).toEqual({ state: 'unknown', alarm: null, job: 'benchy.gcode', alarms: [] });
    expect(ticks[1]).toEqual({ state: 'running', alarm: null, job: 'benchy.gcode', alarms: [] });
    expect(ticks[2]).toEqual({
      state: 'running',
      alarm: expect.stringMatching(/^Server exception: raised CONSTRAINT_ERROR/),
      job: 'benchy.gcode',
      // recoverable: a warning
      alarms: [
        expect.objectContaining({ severity: 'warning', text: expect.stringMatching(/^Server exception/) }),
      ],
    });
  });

  it('reads the 2025 flat ticks', () => {
    const ticks = FLAT.filter((l) => firstKey(l) === 'Status').map(readPruntFrame);
    expect(ticks.length).toBeGreaterThan(0);
    for (const t of ticks) expect(t).toMatchObject({ alarm: null });
    expect(
      readPruntFrame('{"Status":{"Current_File_Name":"","Stepgen_Is_Paused":true,"Startup":"Done"}}'),
    ).toEqual({
      state: 'paused',
      alarm: null,
      job: null,
      alarms: [],
    });
    expect(
      readPruntFrame('{"Status":{"Current_File_Name":"uploads/a.gcode","Startup":"Update_Required"}}'),
    ).toEqual({
      state: 'alarm',
      alarm: expect.stringMatching(/^Firmware update required/),
      job: 'a.gcode',
      alarms: [expect.objectContaining({ text: expect.stringMatching(/^Firmware update required/) })],
    });
  });

  it('reads a fatal server exception as an alarm', () => {
    const f =
      '{"Status_Values":{}, "Server_Exception":{"Message":"raised X : boom","Fatal":true}, "Startup": "Done"}';
    expect(readPruntFrame(f)).toEqual({
      state: 'alarm',
      alarm: 'Server exception: raised X : boom',
      job: null,
      // fatal: critical (the alarm centre's banner)
      alarms: [expect.objectContaining({ severity: 'critical', text: 'Server exception: raised X : boom' })],
    });
  });

  it('says nothing for other frames and garbage, never throws', () => {
    for (const l of [...FLAT, ...MODULE].filter(
      (x) => !['Status', 'Status_Values'].includes(firstKey(x) ?? ''),
    ))
      expect(readPruntFrame(l), l.slice(0, 30)).toBeNull();
    for (const f of ['', 'garbage', '[]', '{"Status_Values":"x"}', '{"Status":7}', '{'])
      expect(readPruntFrame(f), f).toBeNull();
  });
});
