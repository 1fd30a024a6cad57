import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { WatchDecl, WatchSummary } from '../src/fleet/contract';
import { MachineWatch, nextJobRecord } from './watch';

const S = (state: WatchSummary['state'], job: string | null = null, progress?: number): WatchSummary => ({
  state,
  alarm: null,
  job,
  ...(progress === undefined ? {} : { progress }),
});

describe('the server job record (issue 33 item 6)', () => {
  beforeEach(() => vi.useFakeTimers());
  afterEach(() => vi.useRealTimers());

  it('starts when first seen running, keeps its start and name, ends when idle', () => {
    let r = nextJobRecord(null, S('idle'), S('running', 'a.nc', 0.1), 1000);
    expect(r).toEqual({ name: 'a.nc', startedAt: 1000, startSeen: true, progress: 0.1 });
    r = nextJobRecord(r, S('running', 'a.nc'), S('running', null, 0.5), 5000);
    expect(r).toEqual({ name: 'a.nc', startedAt: 1000, startSeen: true, progress: 0.5 });
    r = nextJobRecord(r, S('running'), S('offline'), 6000);
    expect(r?.startedAt).toBe(1000);
    r = nextJobRecord(r, S('offline'), S('paused', 'b.nc'), 7000);
    expect(r).toMatchObject({ name: 'b.nc', startedAt: 7000, startSeen: true });
    expect(nextJobRecord(r, S('paused'), S('idle'), 8000)).toBeNull();
  });
  it('found under way at the first reading: the start was not seen', () => {
    expect(nextJobRecord(null, S('unknown'), S('running'), 1)?.startSeen).toBe(false);
  });
  it('the watch keeps it across readings (a g2core job named by its job list)', async () => {
    const reads: string[] = [];
    const decl: WatchDecl = {
      everyMs: 1000,
      poll: { path: '/status_report', read: () => S('running') },
      jobPoll: { path: '/job', read: () => ({ job: 'part.nc', progress: 0.25 }) },
    };
    const w = new MachineWatch('m', decl, {
      read: async (p) => {
        reads.push(p);
        return { status: 200, body: '{}' };
      },
      report: () => undefined,
      now: () => Date.now(),
    });
    vi.setSystemTime(10_000);
    w.start();
    await vi.advanceTimersByTimeAsync(2500);
    expect(reads).toContain('/job');
    expect(w.job).toMatchObject({ name: 'part.nc', progress: 0.25, startSeen: false });
    const started = w.job?.startedAt;
    await vi.advanceTimersByTimeAsync(5000);
    expect(w.job?.startedAt).toBe(started);
    expect(w.current.job).toBe('part.nc');
    w.stop();
  });
});
