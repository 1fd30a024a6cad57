import { readdirSync, readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import {
  createdId,
  errorBody,
  exceptionReport,
  machineTreeResponse,
  machineValueResponse,
  opState,
  settingsGroup,
  shallowResponse,
  statusReportResponse,
  unwrapEnvelope,
  valueForKey,
  versionResponse,
  jobListResponse,
  operationListResponse,
  operationResponse,
} from './wire';

const FIX = join(process.cwd(), 'tests/fixtures/g2core');
const json = (p: string): unknown => JSON.parse(readFileSync(join(FIX, p), 'utf8'));
const rxLines = (p: string): unknown[] =>
  readFileSync(join(FIX, p), 'utf8')
    .split('\n')
    .filter((l) => l.trim() !== '')
    .map((l) => JSON.parse(l) as { dir: string; raw: string })
    .filter((l) => l.dir === 'rx')
    .map((l) => JSON.parse(l.raw) as unknown);

describe('REST design examples', () => {
  it('GET /version', () => {
    const v = versionResponse.parse(json('rest-design-examples/GET-version.json'));
    expect(v.fb).toBe(100.12);
    expect(v.fbs).toBe('100.12-14-g375c-dirty');
    expect(v.hp).toBe(3);
    expect(v.msg).toBe('SYSTEM READY');
  });

  it('GET /machine: the full tree of groups', () => {
    const t = machineTreeResponse.parse(json('rest-design-examples/GET-machine.json'));
    expect(Object.keys(t.value)).toHaveLength(41);
    expect(t.value.x).toMatchObject({ am: 1, vm: 40000, tn: 0, tm: 420 });
    expect(t.value.he1).toMatchObject({ e: false, at: false });
  });

  it('GET /machine/ct: wrapped value with code 0', () => {
    const r = machineValueResponse.parse(json('rest-design-examples/GET-machine-ct.json'));
    expect(r.value).toBe(0.01);
    expect(r.code).toBe(0);
  });

  it('GET /status_report: wrapped in the examples, bare in the design text', () => {
    const wrapped = statusReportResponse.parse(json('rest-design-examples/GET-status_report.json'));
    expect(wrapped).toMatchObject({ line: 101, posx: 10, stat: 5, momo: 0 });
    const bare = statusReportResponse.parse({ posx: 10.2 });
    expect(bare).toEqual({ posx: 10.2 });
  });

  it('GET /status_report with a filter: request of nulls, answer of values', () => {
    const f = json('rest-design-examples/GET-status_report-filtered.json') as {
      request: { value: Record<string, null> };
      response: unknown;
    };
    const r = statusReportResponse.parse(f.response);
    expect(Object.keys(r).sort()).toEqual(Object.keys(f.request.value).sort());
  });

  it('POST /operation: 201 with a bare id; opstate enums in upper case', () => {
    const f = json('rest-design-examples/POST-operation.json') as {
      response: { body: unknown };
      enums: { opstate: string[] };
    };
    expect(createdId.parse(f.response.body)).toBe('42');
    expect(f.enums.opstate.map((s) => opState.parse(s).state)).toEqual(['pend', 'run', 'done', 'error']);
    expect(opState.parse('wobble')).toEqual({ state: 'unknown', raw: 'wobble' });
  });
});

describe('firmware captures', () => {
  it('startup banner (101.03): hp/hv as strings, envelope r/f', () => {
    const v = versionResponse.parse(json('responses/startup-system-ready-101.03.json'));
    expect(v.hp).toBe('ArduinoDue');
    expect(v.hv).toBe('na');
    expect(v.fb).toBe(101.03);
  });

  it('sys group dump (100.26) and x-axis group with a null value', () => {
    const sys = unwrapEnvelope(json('responses/sys-group-dump-100.26.json')) as { sys: unknown };
    expect(settingsGroup.parse(sys.sys)).toMatchObject({ fb: 100.26, lim: 1, si: 250 });
    const x = unwrapEnvelope(json('responses/x-axis-group.json')) as { x: unknown };
    expect(settingsGroup.parse(x.x)).toMatchObject({ jd: null, vm: 40000 });
  });

  it('config groups (100.12) parse as the machine tree', () => {
    const t = machineTreeResponse.parse({ value: json('responses/config-groups-100.12.json') });
    expect(t.value['1']).toMatchObject({ ma: 0, mi: 8 });
  });

  it('error companion line and exception report', () => {
    const lines = readFileSync(join(FIX, 'responses/error-unrecognized-name-101.03.jsonl'), 'utf8')
      .split('\n')
      .filter(Boolean)
      .map((l) => JSON.parse(l) as unknown);
    expect(errorBody.parse(lines[1]).status).toMatchObject({ code: 100 });
    expect(exceptionReport.parse(json('responses/exception-report-kill-job-101.03.json'))).toMatchObject({
      code: 207,
    });
  });

  it('enq ack is not an error body', () => {
    expect(errorBody.safeParse(json('responses/enq-ack.json')).success).toBe(false);
  });

  it('every status report line of every session parses to numbers', () => {
    const files = readdirSync(join(FIX, 'sessions')).filter((f) => f.endsWith('.jsonl'));
    expect(files.length).toBeGreaterThanOrEqual(10);
    let count = 0;
    for (const f of files) {
      for (const rx of rxLines(join('sessions', f))) {
        const o = rx as Record<string, unknown>;
        const r = o.r as Record<string, unknown> | undefined;
        const sr = o.sr ?? r?.sr;
        if (sr) {
          const parsed = statusReportResponse.parse(o.sr ? { sr } : { r: { sr }, f: o.f });
          for (const v of Object.values(parsed)) expect(typeof v).toBe('number');
          count++;
        }
        if (o.err) expect(errorBody.parse(o).status.code).toBe(100);
        if (o.er) expect(exceptionReport.parse(o).code).toBe(207);
      }
    }
    expect(count).toBeGreaterThan(30);
  });
});

describe('leniency', () => {
  it('coerces numbers sent as strings and keeps other strings', () => {
    expect(statusReportResponse.parse({ posx: '1.5', stat: '5', msg: 'hi' })).toEqual({
      posx: 1.5,
      stat: 5,
      msg: 'hi',
    });
  });

  it('fails with a path on a nested object in a status report', () => {
    const r = statusReportResponse.safeParse({ posx: { a: 1 } });
    expect(r.success).toBe(false);
    if (!r.success) expect(r.error.issues[0]?.path).toEqual(['posx']);
  });

  it('reads a key in every accepted form', () => {
    expect(valueForKey(40000, 'x', 'vm')).toBe(40000);
    expect(valueForKey({ x: { vm: 1 } }, 'x', 'vm')).toBe(1);
    expect(valueForKey({ xvm: 2 }, 'x', 'vm')).toBe(2);
    expect(valueForKey({ 'x.vm': 3 }, 'x', 'vm')).toBe(3);
    expect(valueForKey({ g54: { x: 1 } }, null, 'g54')).toEqual({ x: 1 });
  });

  it('shallow listing accepts true or null', () => {
    expect(Object.keys(shallowResponse.parse({ value: { sys: true, x: null } }).value)).toEqual(['sys', 'x']);
  });

  it('jobs and operations: unknown states are explicit', () => {
    const jobs = jobListResponse.parse([
      { id: 1, name: 'a', state: 'Frobbing', lines: '10', done: 2, started: 5 },
    ]);
    expect(jobs[0]).toMatchObject({
      id: '1',
      state: { state: 'unknown', raw: 'Frobbing' },
      lines: 10,
      started: 5,
    });
    const op = operationResponse.parse({ opstate: 'RUN', value: ['G0 X1'], line: 0 });
    expect(op.opstate.state).toBe('run');
  });
});

describe('operation list (GET /operation, settled by the console)', () => {
  it('accepts a bare array or a value envelope; unknown opstates stay explicit', () => {
    const bare = operationListResponse.parse([
      { id: 43, optype: 'run', opstate: 'run', value: ['G1 X10 F300'], line: 0 },
      { id: 42, optype: 'run', opstate: 'SOMETHING', value: 'G0 X1\n', line: 1 },
    ]);
    expect(bare.map((o) => [o.id, o.opstate.state])).toEqual([
      [43, 'run'],
      [42, 'unknown'],
    ]);
    expect(bare[1]!.opstate.raw).toBe('SOMETHING');
    expect(operationListResponse.parse({ value: [{ id: '7', opstate: 'pend' }] })[0]!.id).toBe('7');
    expect(operationListResponse.safeParse({ value: [{ id: 1 }] }).success).toBe(false);
  });
});
