import { describe, expect, it } from 'vitest';
import { floorPercent, formatJob, jobFactsOf, UNNAMED_JOB } from './job-facts';

describe('job facts (issue 33 item 6)', () => {
  const now = 1_000_000;
  it('takes name, start and progress from the server record over the live reading', () => {
    const f = jobFactsOf(
      { name: 'Job', progress: 0.5, elapsed: 1, remaining: null },
      {
        record: { name: 'tmp.gcode', elapsedMs: 600_000, startSeen: true, progress: 0.169 },
        receivedAt: now,
      },
      now,
    );
    expect(f?.name).toBe('tmp.gcode');
    expect(f?.startedAt).toBe(now - 600_000);
    const w = formatJob(f!, now);
    expect(w.percent).toMatch(/^16\s?%$/);
    expect(w.fraction).toBe(0.16);
    expect(w.runningFor).toBe('running for 10 min 00 s');
  });
  it('estimates time left from the record when the start was seen, says so, and never invents it', () => {
    const rec = { name: 'a.nc', elapsedMs: 85_000, startSeen: true, progress: 0.85 };
    const w = formatJob(jobFactsOf(null, { record: rec, receivedAt: now }, now)!, now);
    expect(w.remaining).toBe('about 15 s left (estimate)');
    const older = formatJob(
      jobFactsOf(null, { record: { ...rec, startSeen: false }, receivedAt: now }, now)!,
      now,
    );
    expect(older.remaining).toBe('remaining: cannot estimate');
    expect(older.runningFor).toBe('running for at least 1 min 25 s');
  });
  it('keeps the start across page loads: the same record received later gives the same start', () => {
    const a = jobFactsOf(
      null,
      { record: { name: null, elapsedMs: 5000, startSeen: true, progress: null }, receivedAt: now },
      now,
    );
    const b = jobFactsOf(
      null,
      {
        record: { name: null, elapsedMs: 65_000, startSeen: true, progress: null },
        receivedAt: now + 60_000,
      },
      now + 60_000,
    );
    expect(b?.startedAt).toBe(a?.startedAt);
    expect(formatJob(b!, now + 60_000).name).toBe(UNNAMED_JOB);
    expect(formatJob(b!, now + 60_000).percent).toBe('progress unknown');
  });
  it('rounds down, one way', () => {
    expect(floorPercent(0.169)).toBe(0.16);
    expect(floorPercent(0.17)).toBe(0.17);
    expect(floorPercent(1)).toBe(1);
  });
  it('uses the live reading only without a record', () => {
    const f = jobFactsOf({ name: 'x', progress: 0.2, elapsed: 10, remaining: 40 }, null, now);
    expect(f).toMatchObject({ name: 'x', progress: 0.2, startedAt: now - 10_000 });
    expect(jobFactsOf(null, null, now)).toBeNull();
  });
});
