import { describe, expect, it } from 'vitest';
import { jobsSchema, parseAnswer, query, statesSchema } from './api';

const job = {
  id: 1,
  machine: 'x1',
  machineName: 'Laser',
  family: 'xtool',
  name: 'sign.gcode',
  startedAt: 1_700_000_000_000,
  endedAt: null,
  outcome: null,
  runningS: 12.5,
  pausedS: 0,
  progress: null,
  startedBy: null,
  pausedBy: null,
  resumedBy: null,
  stoppedBy: null,
  endAlarm: null,
};

describe('history answers', () => {
  it('a well-formed jobs answer is data', () => {
    const r = parseAnswer(jobsSchema, 200, { jobs: [job], total: 1, limit: 50, offset: 0 }, 'jobs');
    expect(r).toEqual({ ok: true, data: { jobs: [job], total: 1, limit: 50, offset: 0 } });
  });

  it('a malformed answer is an error in words, never data', () => {
    const bad = [
      { jobs: [{ ...job, startedAt: '2026-03-10' }], total: 1, limit: 50, offset: 0 },
      { jobs: [{ ...job, outcome: 'exploded' }], total: 1, limit: 50, offset: 0 },
      { jobs: [{ ...job, runningS: -1 }], total: 1, limit: 50, offset: 0 },
      { jobs: [job] },
      null,
      '<html>',
    ];
    for (const b of bad)
      expect(parseAnswer(jobsSchema, 200, b, 'jobs')).toEqual({
        ok: false,
        status: 200,
        error: 'The jobs answer is malformed.',
      });
    expect(
      parseAnswer(
        statesSchema,
        200,
        {
          from: 0,
          to: 1,
          truncated: false,
          machines: [
            {
              machine: 'a',
              machineName: 'A',
              family: null,
              intervals: [{ state: 'flying', alarm: null, from: 0, to: 1, open: false }],
            },
          ],
        },
        'timeline',
      ).ok,
    ).toBe(false);
  });

  it("the server's refusal is shown in its words, else by its status", () => {
    expect(parseAnswer(jobsSchema, 400, { error: 'from must be before to' }, 'jobs')).toEqual({
      ok: false,
      status: 400,
      error: 'from must be before to',
    });
    expect(parseAnswer(jobsSchema, 503, null, 'jobs')).toEqual({
      ok: false,
      status: 503,
      error: 'The console answered HTTP 503.',
    });
  });

  it('query keeps the set values only', () => {
    expect(query({ machine: '', family: 'xtool', from: 5, to: undefined, q: 'a b' })).toBe(
      '?family=xtool&from=5&q=a+b',
    );
    expect(query({ machine: '' })).toBe('');
  });
});
