import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import type { JsonRecord } from '../../fleet/contract';
import { duetAccess } from './access';
import { duetDeclaration } from './declaration';
import { fixtureJson, fixtureText, patchFiles } from './fixtures.test-util';
import { applyPatch, takeFullModel, type JsonObject } from './patch';
import { DEAD_AFTER_MS, NOOP_EVERY_MS, PING_AFTER_MS, POLL_EVERY_MS } from './session';
import {
  duetFromBrowser,
  duetModelStream,
  duetShareRead,
  duetSharing,
  duetWatch,
  readModelFrame,
  summaryOfModel,
} from './sharing';

/** Path and query as the gateway hands them over (its canonical split). */
function target(raw: string): { path: string; query: URLSearchParams } {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { path: t.path, query: t.query };
}
const share = (raw: string) => {
  const t = target(raw);
  return duetShareRead(t.path, t.query);
};

const model = (): JsonObject => fixtureJson('object-model/model_geminiv2.json');

/** The gemini model with a print running (no public capture of one exists: SOURCES.md). */
function printing(status = 'processing'): JsonObject {
  return applyPatch(model(), {
    state: { status },
    job: { file: { fileName: '0:/gcodes/Veil_Token.gcode', size: 594195 }, filePosition: 1000 },
  }).model;
}

describe('duet sharing: the declaration', () => {
  it('is what the declaration gives the gateway', () => {
    expect(duetDeclaration.gateway?.sharing).toBe(duetSharing);
    expect(duetDeclaration.gateway?.session).toBeDefined();
    expect(duetSharing.keepAlive).toBe(true);
    expect(duetSharing.maxConcurrentReads).toBe(4);
  });
});

describe('duet sharing: reads', () => {
  it('shares the model and noop polls with the periods the browser polls them', () => {
    expect(share('/machine/model')).toBe(POLL_EVERY_MS);
    expect(share('/machine/noop')).toBe(NOOP_EVERY_MS);
    // ASP.NET routes in any letter case, with a trailing slash
    expect(share('/Machine/Model/')).toBe(POLL_EVERY_MS);
  });

  it('shares nothing else: on-demand reads, the held session, anything with a query', () => {
    for (const raw of [
      '/machine/model?sessionKey=x',
      '/machine/model?x=1',
      '/machine/status',
      '/machine/connect',
      '/machine/connect?password=reprap',
      '/machine/disconnect',
      '/machine/directory/0%3A%2Fgcodes',
      '/machine/fileinfo/0%3A%2Fgcodes%2Fpart.gcode?readThumbnailContent=true',
      '/machine/file/0%3A%2Fgcodes%2Fa.gcode',
      '/machine/file/0%3A%2Fsys%2Fheightmap.csv',
      '/machine/file/0%3A%2Fsys%2Fconfig.g',
      '/machine',
      '/rr_gcode?gcode=M112',
      '/machine/code',
    ])
      expect(share(raw), raw).toBeNull();
  });

  it('never shares a GET the access policy calls a command', () => {
    const gets = [
      '/rr_gcode?gcode=M112',
      '/rr_delete?name=0:/sys/config.g',
      '/rr_model?key=state',
      '/machine/startPlugin',
      '/machine/systemPackage',
      '/machine/code?gcode=M112',
      '/Machine/Model/x',
      '/machine/model',
      '/machine/noop',
    ];
    const commands = gets.filter((raw) => duetAccess({ method: 'GET', ...target(raw) }).command);
    expect(commands.length).toBeGreaterThan(3);
    for (const raw of commands) expect(share(raw), raw).toBeNull();
  });
});

describe('duet sharing: WS /machine as a model stream', () => {
  const s = duetModelStream;

  it('matches the socket path as ASP.NET routes it, nothing else', () => {
    expect(s.matches('/machine')).toBe(true);
    expect(s.matches('/Machine/')).toBe(true);
    expect(s.matches('/machine/model')).toBe(false);
    expect(s.matches('/')).toBe(false);
  });

  it('takes the first frame as the model, without its messages', () => {
    const full = s.full(fixtureText('object-model/model_geminiv2.json'));
    if (full instanceof Error) throw full;
    expect(full).toEqual(takeFullModel(model()).model);
    expect(full['messages']).toEqual([]);
  });

  it('refuses a first frame that is no JSON object (an Error, no throw)', () => {
    for (const bad of ['PONG\n', '', 'not json', '[1,2]', '"x"', 'null', '{"a":'])
      expect(s.full(bad), bad).toBeInstanceOf(Error);
  });

  it('applies every fixture patch, handing back its messages as events', () => {
    const start = takeFullModel(model()).model;
    for (const file of patchFiles()) {
      const r = s.apply(start, fixtureText(file));
      if (r instanceof Error) throw r;
      const want = applyPatch(start, fixtureJson(file));
      expect(r.model, file).toEqual(want.model);
      expect(r.events, file).toEqual(want.messages);
    }
    const m = s.apply(start, fixtureText('patches/dsf-python/test_messages_1__messages-new.json'));
    if (m instanceof Error) throw m;
    expect(m.events).toHaveLength(1);
  });

  it('refuses a patch that is no JSON object, and lets a PONG change nothing', () => {
    const start = takeFullModel(model()).model;
    for (const bad of ['', 'garbage', '[]', '42']) expect(s.apply(start, bad), bad).toBeInstanceOf(Error);
    expect(s.apply(start, 'PONG\n')).toEqual({ model: start, events: [] });
  });

  it('diffs to one frame that a browser applies to get the same model and the events', () => {
    let m: JsonRecord = takeFullModel(model()).model;
    const from = m;
    const events = [];
    for (const file of patchFiles()) {
      const r = s.apply(m, fixtureText(file));
      if (r instanceof Error) throw r;
      m = r.model;
      events.push(...r.events);
    }
    const frame = s.diff(from, m, events);
    const got = applyPatch(from, JSON.parse(frame) as JsonObject);
    expect(got.model).toEqual(m);
    expect(got.messages).toEqual(events);
    // the first frame for a browser that joins is the whole model, which it takes as its model
    expect(takeFullModel(JSON.parse(s.first(m)) as JsonObject).model).toEqual(m);
  });

  it('acknowledges with OK\\n and answers the browser as DSF does', () => {
    expect(s.ack).toBe('OK\n');
    expect(duetFromBrowser('OK\n')).toEqual({ ack: true });
    expect(duetFromBrowser('OK')).toEqual({ ack: true });
    expect(duetFromBrowser('OK\r\n')).toEqual({ ack: true });
    // DSF's exact answer (WebSocketController: "PONG\n"); the browser trims it (ingest.ts)
    expect(duetFromBrowser('PING\n')).toEqual({ reply: 'PONG\n' });
    expect(duetFromBrowser('PING')).toEqual({ reply: 'PONG\n' });
  });

  it('drops anything else a browser sends (DSF would close the socket)', () => {
    for (const bad of ['', '\n', 'ok\n', ' OK', 'OK ', 'PONG\n', 'OK\nPING\n', 'M112\n', '{"a":1}', 'OKAY'])
      expect(duetFromBrowser(bad), JSON.stringify(bad)).toBeNull();
  });

  it('pings a silent upstream as the browser did, and knows the answer', () => {
    expect(s.ping?.frame).toBe('PING\n');
    expect(s.ping?.everyMs).toBe(PING_AFTER_MS);
    expect(s.ping?.everyMs).toBeLessThan(PING_AFTER_MS + DEAD_AFTER_MS);
    expect(s.ping?.isPong('PONG\n')).toBe(true);
    expect(s.ping?.isPong('{"state":{}}')).toBe(false);
  });
});

describe('duet sharing: the watch', () => {
  it('reads the whole model every 10 s and keeps the socket', () => {
    expect(duetWatch.poll?.path).toBe('/machine/model');
    expect(duetWatch.stream?.path).toBe('/machine');
    expect(duetModelStream.matches(duetWatch.stream?.path ?? '')).toBe(true);
    expect(duetWatch.everyMs).toBe(10_000);
  });

  it('reads the real idle model', () => {
    expect(duetWatch.poll?.read(200, fixtureText('object-model/model_geminiv2.json'))).toEqual({
      state: 'idle',
      alarm: null,
      job: null,
      alarms: [],
      progress: null,
    });
    // the virgin model has a message box open: the console shows it as a warning, so does the watch
    expect(duetWatch.poll?.read(200, fixtureText('object-model/model_virgin.json'))).toEqual({
      state: 'idle',
      alarm: 'Message from the machine: title',
      job: null,
      alarms: [
        {
          key: expect.stringMatching(/^messagebox-/),
          severity: 'warning',
          text: 'Message from the machine: title',
        },
      ],
      progress: null,
    });
  });

  it('reads a print, a pause, a halt and a heater fault', () => {
    expect(summaryOfModel(printing())).toEqual({
      state: 'running',
      alarm: null,
      job: 'Veil_Token.gcode',
      alarms: [],
      // filePosition / file.size of the fixture's print
      progress: expect.closeTo(0.00168, 5),
    });
    expect(summaryOfModel(printing('paused'))).toMatchObject({ state: 'paused' });
    expect(summaryOfModel(printing('halted'))).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/halted/),
      alarms: [{ key: 'halted', severity: 'critical', text: expect.stringMatching(/halted/) }],
    });
    const fault = applyPatch(model(), { heat: { heaters: [{}, { state: 'fault' }] } }).model;
    expect(summaryOfModel(fault)).toMatchObject({
      alarm: expect.stringMatching(/Heater fault/),
      alarms: [{ key: 'heater-1-fault', severity: 'critical', text: expect.stringMatching(/Heater fault/) }],
    });
  });

  it('turns failures and garbage into an Error, never a throw', () => {
    const read = duetWatch.poll?.read ?? (() => new Error('no poll'));
    expect(read(403, '')).toBeInstanceOf(Error);
    expect(read(503, 'DCS is unavailable')).toBeInstanceOf(Error);
    expect(read(200, '<html>')).toBeInstanceOf(Error);
    expect(read(200, '[]')).toBeInstanceOf(Error);
    expect(read(200, '{"boards":"x"}')).toBeInstanceOf(Error);
    // the schema is lenient: an unknown status is read as unknown, not refused
    expect(read(200, '{"state":{"status":42}}')).toMatchObject({ state: 'unknown' });
  });

  it('reads socket frames: a whole model fully, a patch for what it says for certain', () => {
    expect(readModelFrame(fixtureText('object-model/model_geminiv2.json'))).toEqual({
      state: 'idle',
      alarm: null,
      job: null,
      alarms: [],
      progress: null,
    });
    expect(readModelFrame('{"state":{"status":"processing","upTime":5}}')).toEqual({ state: 'running' });
    expect(readModelFrame('{"state":{"status":"halted"}}')).toEqual({
      state: 'alarm',
      alarm: 'Emergency stop: the machine is halted',
      // A patch raises (it cannot clear): the same key as the page's alarm.
      raise: [{ key: 'halted', severity: 'critical', text: 'Emergency stop: the machine is halted' }],
    });
    expect(readModelFrame('{"heat":{"heaters":[{},{"state":"fault"}]}}')).toEqual({
      state: 'alarm',
      alarm: 'Heater fault: heater 1',
      raise: [{ key: 'heater-1-fault', severity: 'critical', text: 'Heater fault: heater 1' }],
    });
    expect(
      readModelFrame(fixtureText('patches/dsf-python/test_job_1__job-file-with-thumbnail.json')),
    ).toEqual({
      job: 'Veil_Token.gcode',
    });
    expect(readModelFrame('{"job":{"file":{"fileName":null}}}')).toEqual({ job: null });
  });

  it('says nothing for frames without news, PONG and garbage', () => {
    for (const f of [
      '{"state":{"upTime":5}}',
      fixtureText('patches/dsf-python/test_messages_1__messages-new.json'),
      'PONG\n',
      '',
      'garbage',
      '[1]',
      '{"state":{"status":{"x":1}}}',
    ])
      expect(readModelFrame(f), f.slice(0, 40)).toBeNull();
  });
});
