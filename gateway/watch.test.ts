import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { WatchDecl, WatchSummary } from '../src/fleet/contract';
import { xtoolWatch } from '../src/controllers/xtool/sharing';
import { describeChange, MachineWatch, type WatchEvent } from './watch';

beforeEach(() => {
  vi.useFakeTimers();
  vi.spyOn(Math, 'random').mockReturnValue(0); // no start jitter
});
afterEach(() => {
  vi.useRealTimers();
  vi.restoreAllMocks();
});

const S = (
  state: WatchSummary['state'],
  job: string | null = null,
  alarm: string | null = null,
): WatchSummary => ({
  state,
  job,
  alarm,
});

describe('describeChange', () => {
  it('names job starts, pauses, resumes and ends, and alarms raised and cleared', () => {
    expect(describeChange(S('idle'), S('running', 'a.nc'))).toEqual([
      { what: 'job started', detail: 'a.nc' },
    ]);
    expect(describeChange(S('running', 'a.nc'), S('paused', 'a.nc'))).toEqual([
      { what: 'job paused', detail: 'a.nc' },
    ]);
    expect(describeChange(S('paused', 'a.nc'), S('running', 'a.nc'))).toEqual([
      { what: 'job resumed', detail: 'a.nc' },
    ]);
    expect(describeChange(S('running', 'a.nc'), S('idle'))).toEqual([{ what: 'job ended', detail: 'a.nc' }]);
    expect(describeChange(S('running', 'a.nc'), S('alarm', 'a.nc', 'flame detected'))).toEqual([
      { what: 'alarm', detail: 'flame detected' },
    ]);
    expect(describeChange(S('alarm', null, 'flame detected'), S('idle'))).toEqual([
      { what: 'alarm cleared', detail: 'flame detected' },
    ]);
    expect(describeChange(S('running', 'a.nc'), S('running', 'a.nc'))).toEqual([]);
    // Not knowing is not an event.
    expect(describeChange(S('running', 'a.nc'), S('unknown'))).toEqual([]);
  });
});

describe('MachineWatch', () => {
  it('polls every everyMs with nobody watching and reports each change once', async () => {
    const answers = [
      { status: 200, body: 'idle' },
      { status: 200, body: 'running:part.nc' },
      { status: 200, body: 'running:part.nc' },
      { status: 200, body: 'idle' },
    ];
    const reads: string[] = [];
    const events: WatchEvent[] = [];
    const decl: WatchDecl = {
      everyMs: 10_000,
      poll: {
        path: '/status',
        read: (status, body) => {
          if (status !== 200) return new Error(`HTTP ${status}`);
          const [state, job] = body.split(':');
          return S(state === 'running' ? 'running' : 'idle', job ?? null);
        },
      },
    };
    const w = new MachineWatch('m1', decl, {
      read: (p) => {
        reads.push(p);
        return Promise.resolve(answers.shift() ?? { status: 200, body: 'idle' });
      },
      report: (e) => events.push(e),
    });
    w.start();
    await vi.advanceTimersByTimeAsync(1); // the first poll at once (no jitter here)
    expect(reads).toEqual(['/status']);
    await vi.advanceTimersByTimeAsync(9_990);
    expect(reads).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(29_990);
    expect(reads).toHaveLength(4);
    expect(events.map((e) => `${e.what} ${e.detail}`)).toEqual(['job started part.nc', 'job ended part.nc']);
    w.stop();
    await vi.advanceTimersByTimeAsync(60_000);
    expect(reads).toHaveLength(4);
  });

  it('lookNow reads at once, and once more right after a poll in flight, so a cleared-and-raised alarm is seen as two', async () => {
    let state = 'running';
    let gate: (() => void) | null = null;
    const reads: string[] = [];
    const events: WatchEvent[] = [];
    const decl: WatchDecl = {
      everyMs: 10_000,
      poll: {
        path: '/status',
        read: (_s, body) => (body === 'alarm' ? S('alarm', null, 'panic') : S('running')),
      },
    };
    const w = new MachineWatch('m1', decl, {
      read: async () => {
        const seen = state;
        reads.push(seen);
        if (gate === null && reads.length === 3) await new Promise<void>((r) => (gate = r));
        return { status: 200, body: seen };
      },
      report: (e) => events.push(e),
    });
    w.start();
    await vi.advanceTimersByTimeAsync(1);
    expect(reads).toEqual(['running']);
    state = 'alarm';
    w.lookNow();
    await vi.advanceTimersByTimeAsync(1);
    expect(reads).toEqual(['running', 'alarm']);
    // Cleared: the read starts and is held in flight while the alarm is raised again.
    state = 'running';
    w.lookNow();
    await vi.advanceTimersByTimeAsync(1);
    expect(reads).toHaveLength(3);
    state = 'alarm';
    w.lookNow(); // during the poll in flight: another right after it
    (gate as (() => void) | null)?.();
    await vi.advanceTimersByTimeAsync(1);
    expect(reads).toEqual(['running', 'alarm', 'running', 'alarm']);
    expect(events.filter((e) => e.what === 'alarm')).toHaveLength(2);
    w.stop();
  });

  it('keeps the last summary through an unreachable controller or a bad answer, without throwing; a bad answer is said ("not read by the server")', async () => {
    let n = 0;
    const events: WatchEvent[] = [];
    const w = new MachineWatch(
      'm1',
      {
        everyMs: 1000,
        poll: { path: '/s', read: (_s, body) => (body === 'run' ? S('running') : new Error('garbage')) },
      },
      {
        read: () => {
          n++;
          if (n === 1) return Promise.resolve({ status: 200, body: 'run' });
          if (n === 2) return Promise.reject(new Error('ECONNREFUSED'));
          return Promise.resolve({ status: 200, body: '<html>' });
        },
        report: (e) => events.push(e),
      },
    );
    w.start();
    await vi.advanceTimersByTimeAsync(5000);
    expect(n).toBeGreaterThanOrEqual(3);
    expect(w.current.state).toBe('running');
    expect(w.current.unread).toBe('garbage');
    expect(events.map((e) => e.what)).toEqual(['job started', 'not read by the server']);
    w.stop();
  });

  it('reads again at once when its read taught the family another poll (a Duet found standalone), and holds a stream declared later', async () => {
    const api: { v: 'unknown' | 'dsf' } = { v: 'unknown' };
    const first = { path: '/machine/model', read: () => new Error('not JSON') };
    const second = { path: '/rr_model', read: () => S('idle') };
    const paths: string[] = [];
    const holds: string[] = [];
    const decl: WatchDecl = {
      everyMs: 1000,
      get poll() {
        return paths.length === 0 ? first : second;
      },
      get stream() {
        return api.v === 'dsf' ? { path: '/machine', read: () => null } : undefined;
      },
    };
    const events: WatchEvent[] = [];
    const w = new MachineWatch('d1', decl, {
      read: (p) => {
        paths.push(p);
        return Promise.resolve({ status: 200, body: '' });
      },
      hold: (p) => {
        holds.push(p);
        return Promise.resolve(() => undefined);
      },
      report: (e) => events.push(e),
    });
    w.start();
    await vi.advanceTimersByTimeAsync(2100);
    expect(paths.slice(0, 2)).toEqual(['/machine/model', '/rr_model']);
    expect(w.current).toMatchObject({ state: 'idle', unread: null });
    expect(events.map((e) => e.what)).not.toContain('not read by the server');
    expect(holds).toEqual([]);
    api.v = 'dsf';
    await vi.advanceTimersByTimeAsync(1100);
    expect(holds).toEqual(['/machine']);
    await vi.advanceTimersByTimeAsync(3000);
    expect(holds).toEqual(['/machine']);
    w.stop();
  });

  it('holds the stream open, reads its frames, and opens it again after it ended', async () => {
    const holds: Array<{ onFrame: (f: string) => void; onEnd: () => void; released: boolean }> = [];
    const events: WatchEvent[] = [];
    const w = new MachineWatch(
      'x1',
      {
        everyMs: 5000,
        stream: {
          path: '/',
          read: (f) => (f === 'err:flameCheck' ? { state: 'alarm', alarm: 'flame' } : null),
        },
      },
      {
        read: () => Promise.reject(new Error('no polls here')),
        hold: (_p, onFrame, onEnd) => {
          const h = { onFrame, onEnd, released: false };
          holds.push(h);
          return Promise.resolve(() => {
            h.released = true;
          });
        },
        report: (e) => events.push(e),
      },
    );
    w.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(holds).toHaveLength(1);
    holds[0]?.onFrame('ok:IDLE');
    holds[0]?.onFrame('err:flameCheck');
    expect(events.map((e) => `${e.what}: ${e.detail}`)).toEqual(['alarm: flame']);
    holds[0]?.onEnd();
    // Listened to again after 1 s (not everyMs): a flame sent meanwhile is not missed for long.
    await vi.advanceTimersByTimeAsync(999);
    expect(holds).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(1);
    expect(holds).toHaveLength(2);
    w.stop();
    expect(holds[1]?.released).toBe(true);
  });

  it('an xTool job loaded by software and started with the button keeps its name through polls that name none (issue 33, 6)', async () => {
    let working = '0';
    const holds: Array<(f: string) => void> = [];
    const w = new MachineWatch('laser', xtoolWatch, {
      read: () => Promise.resolve({ status: 200, body: `{"result":"ok","working":"${working}"}` }),
      hold: (_p, onFrame) => {
        holds.push(onFrame);
        return Promise.resolve(() => undefined);
      },
      report: () => undefined,
    });
    w.start();
    await vi.advanceTimersByTimeAsync(1);
    expect(w.job).toBeNull();
    // Loaded and waiting for the button: the frame names it; the poll reads "2" (running).
    holds[0]?.('ok:WORKING_ONLINE_READY\n');
    working = '2';
    await vi.advanceTimersByTimeAsync(10_000);
    expect(w.current.state).toBe('running');
    expect(w.job?.name).toBe('tmp.gcode');
    // The button: a frame without a name, and more polls without one.
    holds[0]?.('ok:WORKING_OFFLINE\n');
    await vi.advanceTimersByTimeAsync(20_000);
    expect(w.job?.name).toBe('tmp.gcode');
    // Idle: the job is over, and the name is forgotten with it.
    working = '0';
    holds[0]?.('ok:IDLE\n');
    await vi.advanceTimersByTimeAsync(10_000);
    expect(w.job).toBeNull();
    expect(w.current.job).toBeNull();
    // A job from the laser's own memory later: no name, not the old one.
    working = '2';
    holds[0]?.('ok:WORKING_OFFLINE\n');
    await vi.advanceTimersByTimeAsync(10_000);
    expect(w.job).not.toBeNull();
    expect(w.job?.name).toBeNull();
    w.stop();
  });

  it('calls a machine offline after two failed reads in a row (during a job: an event of its own)', async () => {
    const answers: Array<{ status: number; body: string; gateway?: boolean } | Error> = [
      { status: 200, body: 'run' },
      { status: 502, body: '{"error":"cannot reach m1","gateway":true}', gateway: true },
      new Error('ECONNREFUSED'),
      { status: 504, body: '{"error":"timed out","gateway":true}', gateway: true },
      { status: 200, body: 'idle' },
    ];
    const events: WatchEvent[] = [];
    const seen: Array<[string, string]> = [];
    const w = new MachineWatch(
      'm1',
      {
        everyMs: 1000,
        poll: { path: '/s', read: (_s, body) => (body === 'run' ? S('running', 'a.nc') : S('idle')) },
      },
      {
        read: () => {
          const a = answers.shift() ?? { status: 200, body: 'idle' };
          return a instanceof Error ? Promise.reject(a) : Promise.resolve(a);
        },
        report: (e) => events.push(e),
        observe: (prev, next) => seen.push([prev.state, next.state]),
      },
    );
    w.start();
    await vi.advanceTimersByTimeAsync(1);
    expect(w.current.state).toBe('running');
    await vi.advanceTimersByTimeAsync(1000);
    // One failure is not yet offline (a blip).
    expect(w.current.state).toBe('running');
    await vi.advanceTimersByTimeAsync(1000);
    expect(w.current.state).toBe('offline');
    await vi.advanceTimersByTimeAsync(2000);
    expect(w.current.state).toBe('idle');
    expect(events.map((e) => e.what)).toEqual(['job started', 'offline during a job']);
    expect(seen).toEqual([
      ['unknown', 'running'],
      ['running', 'offline'],
      ['offline', 'idle'],
    ]);
    w.stop();
  });

  it('a frame raises alarms beside those already known; the poll’s full list replaces them', async () => {
    let onFrame: (f: string) => void = () => undefined;
    const w = new MachineWatch(
      'd1',
      {
        everyMs: 1000,
        poll: {
          path: '/model',
          read: () => ({ ...S('idle'), alarms: [] }),
        },
        stream: {
          path: '/machine',
          read: (f) => ({
            state: 'alarm',
            raise: [{ key: f, severity: 'critical', text: `fault ${f}` }],
          }),
        },
      },
      {
        read: () => new Promise(() => undefined), // the poll never answers in this test
        hold: (_p, frame) => {
          onFrame = frame;
          return Promise.resolve(() => undefined);
        },
        report: () => undefined,
      },
    );
    w.start();
    await vi.advanceTimersByTimeAsync(0);
    onFrame('heater-0-fault');
    onFrame('heater-1-fault');
    onFrame('heater-0-fault');
    expect(w.current.alarms?.map((a) => a.key)).toEqual(['heater-0-fault', 'heater-1-fault']);
    w.learn({ ...S('idle'), alarms: [] });
    expect(w.current.alarms).toEqual([]);
    w.stop();
  });
});
