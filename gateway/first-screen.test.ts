import { describe, expect, it } from 'vitest';
import { watchForPage } from './api';

/** `watch` in `GET /api/machines` (the fleet page's first screen): controller text made safe. */
describe('watchForPage', () => {
  const scrub = (t: string): string => t.replaceAll('hunter2', '[secret]');
  const summary = {
    state: 'alarm' as const,
    job: 'job-hunter2.nc',
    alarm: `Fault: key hunter2 ${'x'.repeat(500)}`,
    alarms: [
      { key: 'a', severity: 'warning' as const, text: 'w' },
      { key: 'b', severity: 'critical' as const, text: 'c' },
    ],
    progress: 0.4,
  };

  it('scrubs secrets, cuts text short, names the worst severity and gives an age, not a clock time', () => {
    const w = watchForPage({ summary, lastSeen: 9_000 }, 10_500, scrub);
    expect(w).toMatchObject({
      state: 'alarm',
      job: 'job-[secret].nc',
      alarmSeverity: 'critical',
      ageMs: 1500,
    });
    expect(String(w?.['alarm'])).toMatch(/^Fault: key \[secret\] x+$/);
    expect(String(w?.['alarm']).length).toBe(200);
    expect(JSON.stringify(w)).not.toContain('hunter2');
  });

  it('the job record a hostile controller named: scrubbed and cut like the rest, its start an age', () => {
    const name = `<img src=x onerror=alert(1)> hunter2 ${'y'.repeat(5000)}`;
    const w = watchForPage(
      {
        summary: { ...summary, state: 'running' },
        lastSeen: 9_000,
        job: { name, startedAt: 4_000, startSeen: true, progress: 0.5 },
      },
      10_500,
      scrub,
    );
    const rec = w?.['record'] as { name: string; elapsedMs: number } | undefined;
    expect(rec?.name.length).toBe(200);
    expect(rec?.name).toMatch(/^<img src=x onerror=alert\(1\)> \[secret\] y+$/);
    expect(rec?.elapsedMs).toBe(6_500);
    expect(JSON.stringify(w)).not.toContain('hunter2');
  });

  it('leaves out what it does not know: no watch, an unknown state, a progress out of range', () => {
    expect(watchForPage(null, 0, scrub)).toBeUndefined();
    expect(
      watchForPage({ summary: { state: 'unknown', alarm: null, job: null }, lastSeen: null }, 0, scrub),
    ).toBeUndefined();
    const w = watchForPage({ summary: { ...summary, progress: 7 }, lastSeen: null }, 0, scrub);
    expect(w?.['progress']).toBeNull();
    expect(w?.['ageMs']).toBeNull();
  });

  it('a machine the watch cannot read is "unread" with why (scrubbed, cut), never left out', () => {
    const w = watchForPage(
      {
        summary: {
          state: 'unknown',
          alarm: null,
          job: null,
          unread: `not JSON (hunter2 ${'<'.repeat(400)})`,
        },
        lastSeen: 1000,
      },
      3000,
      scrub,
    );
    expect(w).toMatchObject({ state: 'unread', alarm: null, job: null, ageMs: 2000 });
    expect(String(w?.unread)).toMatch(/^not JSON \(\[secret\] </);
    expect(String(w?.unread).length).toBe(200);
  });
});
