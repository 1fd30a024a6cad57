// @vitest-environment happy-dom
import { act, cleanup, renderHook } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { MachineQueries, useMachineQuery, type Fetcher, type QueryOptions } from './query';

/**
 * The query layer's rules (query.ts), with fake timers: one request per key in flight, stale
 * times, invalidation of what is watched, cancellation on clear, the bounded cache (LRU and gc),
 * interval refetches, `enabled`, and the view `useMachineQuery` gives.
 */

beforeEach(() => {
  vi.useFakeTimers();
  vi.setSystemTime(new Date('2026-03-01T12:00:00Z'));
});
afterEach(() => {
  cleanup();
  vi.useRealTimers();
});

/** A read whose answers the test gives, call by call. */
function controlled<T>() {
  const calls: Array<{ signal: AbortSignal; resolve: (v: T) => void; reject: (e: unknown) => void }> = [];
  const fn = vi.fn(
    (signal: AbortSignal) => new Promise<T>((resolve, reject) => calls.push({ signal, resolve, reject })),
  );
  return { fn, calls };
}

/** Lets promises and due timers run (inside act: React sees the updates). */
const flush = (ms = 0) =>
  act(async () => {
    await vi.advanceTimersByTimeAsync(ms);
  });

interface Props<T> {
  parts: readonly unknown[];
  fn: Fetcher<T>;
  opts?: QueryOptions;
}

function watch<T>(q: MachineQueries, initialProps: Props<T>) {
  return renderHook((p: Props<T>) => useMachineQuery(q, p.parts, p.fn, p.opts), { initialProps });
}

describe('MachineQueries: reads', () => {
  it('joins a read in flight: one request per key, every caller gets its answer', async () => {
    const q = new MachineQueries('m');
    const r = controlled<string[]>();
    const a = q.fetch(['files'], r.fn, { staleTimeMs: 5000 });
    const b = q.fetch(['files'], r.fn, { staleTimeMs: 5000 });
    expect(r.fn).toHaveBeenCalledTimes(1);
    const other = q.fetch(['files', '/sub'], r.fn, { staleTimeMs: 5000 });
    expect(r.fn).toHaveBeenCalledTimes(2); // another key is another read
    r.calls[0]!.resolve(['a.gcode']);
    r.calls[1]!.resolve(['b.gcode']);
    expect(await a).toEqual(['a.gcode']);
    expect(await b).toBe(await a);
    expect(await other).toEqual(['b.gcode']);
    // Fresh: from cache, no request.
    expect(await q.fetch(['files'], r.fn, { staleTimeMs: 5000 })).toEqual(['a.gcode']);
    expect(r.fn).toHaveBeenCalledTimes(2);
  });

  it('an answer is fresh for staleTimeMs (10 s when not given), then read again', async () => {
    const q = new MachineQueries('m');
    let n = 0;
    const fn = vi.fn(async () => ++n);
    expect(await q.fetch(['x'], fn, { staleTimeMs: 1000 })).toBe(1);
    await vi.advanceTimersByTimeAsync(999);
    expect(await q.fetch(['x'], fn, { staleTimeMs: 1000 })).toBe(1);
    expect(fn).toHaveBeenCalledTimes(1);
    await vi.advanceTimersByTimeAsync(1);
    expect(await q.fetch(['x'], fn, { staleTimeMs: 1000 })).toBe(2);
    expect(fn).toHaveBeenCalledTimes(2);
    // staleTimeMs 0: always read.
    expect(await q.fetch(['x'], fn, { staleTimeMs: 0 })).toBe(3);

    const d = vi.fn(async () => 'd');
    await q.fetch(['default'], d);
    await vi.advanceTimersByTimeAsync(9_999);
    await q.fetch(['default'], d);
    expect(d).toHaveBeenCalledTimes(1);
    await vi.advanceTimersByTimeAsync(1);
    await q.fetch(['default'], d);
    expect(d).toHaveBeenCalledTimes(2);
  });

  it('writes answers with structural sharing: equal parts keep the previous objects', async () => {
    const q = new MachineQueries('m');
    const answers = [
      { a: { x: 1 }, b: [1] },
      { a: { x: 1 }, b: [2] },
    ];
    const fn = vi.fn(async () => structuredClone(answers[fn.mock.calls.length - 1]!));
    const first = await q.fetch(['s'], fn, { staleTimeMs: 0 });
    await q.fetch(['s'], fn, { staleTimeMs: 0 });
    const shown = q.peek<typeof first>(['s'])!;
    expect(shown).not.toBe(first);
    expect(shown.a).toBe(first.a);
    expect(shown.b).toEqual([2]);
  });

  it('a failed read rejects, keeps the previous answer, is not retried, and makes the key stale', async () => {
    const q = new MachineQueries('m');
    const fn = vi
      .fn<Fetcher<string>>()
      .mockResolvedValueOnce('ok')
      .mockRejectedValueOnce(new Error('boom'))
      .mockResolvedValue('again');
    await q.fetch(['k'], fn, { staleTimeMs: 0 });
    await expect(q.fetch(['k'], fn, { staleTimeMs: 0 })).rejects.toThrow('boom');
    expect(q.peek(['k'])).toBe('ok');
    await vi.advanceTimersByTimeAsync(60_000);
    expect(fn).toHaveBeenCalledTimes(2);
    // An error makes the answer stale whatever its age.
    expect(await q.fetch(['k'], fn, { staleTimeMs: 60 * 60_000 })).toBe('again');
  });

  it('clear() aborts the read in flight; its late answer is never written', async () => {
    const q = new MachineQueries('m');
    const r = controlled<string[]>();
    const read = q.fetch(['files'], r.fn);
    const signal = r.calls[0]!.signal;
    expect(signal.aborted).toBe(false);
    q.clear();
    expect(signal.aborted).toBe(true);
    await expect(read).rejects.toBeInstanceOf(Error);
    r.calls[0]!.resolve(['late.gcode']);
    await vi.advanceTimersByTimeAsync(0);
    expect(q.peek(['files'])).toBeUndefined();
    expect(q.size).toBe(0);
    // The next read asks again (nothing cached, nothing joined).
    const again = q.fetch(['files'], r.fn);
    expect(r.fn).toHaveBeenCalledTimes(2);
    r.calls[1]!.resolve(['new.gcode']);
    expect(await again).toEqual(['new.gcode']);
  });

  it('set() writes an answer got another way: fresh, shared, with its time', async () => {
    const q = new MachineQueries('m');
    const fn = vi.fn(async () => ({ names: ['a'] }));
    const before = await q.fetch(['dir'], fn, { staleTimeMs: 0 });
    await vi.advanceTimersByTimeAsync(500);
    q.set(['dir'], { names: ['a'] });
    expect(q.peek(['dir'])).toBe(before); // equal: the same object
    q.set(['dir'], { names: ['a', 'b'] });
    expect(q.cached(['dir'])).toEqual({ data: { names: ['a', 'b'] }, updatedAt: Date.now() });
    expect(await q.fetch(['dir'], fn, { staleTimeMs: 1000 })).toEqual({ names: ['a', 'b'] });
    expect(fn).toHaveBeenCalledTimes(1);
    expect(q.cached(['none'])).toBeUndefined();
  });
});

describe('MachineQueries: a bounded cache', () => {
  it('beyond maxEntries drops the least recently written entries first', async () => {
    const q = new MachineQueries('m', { maxEntries: 2 });
    const fn = vi.fn(async () => 'v');
    await q.fetch(['x'], fn);
    await vi.advanceTimersByTimeAsync(10);
    await q.fetch(['y'], fn);
    await vi.advanceTimersByTimeAsync(10);
    await q.fetch(['x'], fn, { staleTimeMs: 0 }); // x written again: now y is the oldest
    await q.fetch(['z'], fn);
    expect(q.size).toBe(2);
    expect(q.peek(['y'])).toBeUndefined();
    expect(q.peek(['x'])).toBe('v');
    expect(q.peek(['z'])).toBe('v');
  });

  it('never drops an entry being watched or being read', async () => {
    const q = new MachineQueries('m', { maxEntries: 3 });
    const view = watch(q, { parts: ['shown'], fn: async () => 'S', opts: { staleTimeMs: 60_000 } });
    await flush(10);
    const slow = controlled<string>();
    const first = q.fetch(['slow'], slow.fn);
    slow.calls[0]!.resolve('v1');
    await first;
    void q.fetch(['slow'], slow.fn, { staleTimeMs: 0 }); // read again, in flight
    for (const k of ['a', 'b', 'c', 'd']) {
      await vi.advanceTimersByTimeAsync(10);
      await q.fetch([k], async () => k);
    }
    expect(q.size).toBe(3);
    expect(q.peek(['shown'])).toBe('S'); // the oldest, but on screen
    expect(q.peek(['slow'])).toBe('v1'); // older than a–c, but being read
    expect([q.peek(['a']), q.peek(['b']), q.peek(['c']), q.peek(['d'])]).toEqual([
      undefined,
      undefined,
      undefined,
      'd',
    ]);
    // Once nobody shows it and its read is done, the oldest goes first.
    slow.calls[1]!.resolve('v2');
    view.unmount();
    await flush(10);
    await q.fetch(['e'], async () => 'e');
    expect(q.size).toBe(3);
    expect(q.peek(['shown'])).toBeUndefined();
    expect(q.peek(['slow'])).toBe('v2');
  });

  it('drops an unobserved entry gcTimeMs after its last read, a watched one only once unwatched', async () => {
    const q = new MachineQueries('m', { gcTimeMs: 1000 });
    await q.fetch(['a'], async () => 'A');
    await vi.advanceTimersByTimeAsync(999);
    expect(q.peek(['a'])).toBe('A');
    await vi.advanceTimersByTimeAsync(1);
    expect(q.peek(['a'])).toBeUndefined();
    expect(q.size).toBe(0);

    const view = watch(q, { parts: ['b'], fn: async () => 'B', opts: { staleTimeMs: 60_000 } });
    await flush(5000);
    expect(q.peek(['b'])).toBe('B');
    view.unmount();
    await vi.advanceTimersByTimeAsync(999);
    expect(q.peek(['b'])).toBe('B');
    await vi.advanceTimersByTimeAsync(1);
    expect(q.peek(['b'])).toBeUndefined();
  });
});

describe('useMachineQuery', () => {
  it('loading while the first answer is read, fetching while refreshing; an error is shown with the old answer', async () => {
    const q = new MachineQueries('m');
    const r = controlled<string>();
    const { result } = watch(q, { parts: ['k'], fn: r.fn, opts: { staleTimeMs: 60_000 } });
    await flush();
    expect(result.current).toMatchObject({ data: undefined, loading: true, fetching: true, error: null });
    r.calls[0]!.resolve('one');
    await flush();
    expect(result.current).toMatchObject({ data: 'one', loading: false, fetching: false, error: null });
    expect(result.current.updatedAt).toBe(Date.now());
    act(() => result.current.refetch());
    expect(result.current).toMatchObject({ data: 'one', loading: false, fetching: true });
    r.calls[1]!.reject(new Error('boom'));
    await flush();
    expect(result.current).toMatchObject({ data: 'one', loading: false, fetching: false });
    expect(result.current.error?.message).toBe('boom');
    await flush(120_000);
    expect(r.fn).toHaveBeenCalledTimes(2); // no retry behind the user's back
    act(() => result.current.refetch());
    r.calls[2]!.resolve('two');
    await flush();
    expect(result.current).toMatchObject({ data: 'two', error: null });
  });

  it('shows a cached answer at once and reads only when stale; switching keys shows the new key', async () => {
    const q = new MachineQueries('m');
    await q.fetch(['dir', '/a'], async () => 'A');
    await q.fetch(['dir', '/b'], async () => 'B');
    const r = controlled<string>();
    const opts = { staleTimeMs: 60_000 };
    const { result, rerender } = watch(q, { parts: ['dir', '/a'], fn: r.fn, opts });
    expect(result.current).toMatchObject({ data: 'A', loading: false, fetching: false });
    await flush();
    expect(r.fn).not.toHaveBeenCalled();
    rerender({ parts: ['dir', '/b'], fn: r.fn, opts });
    await flush();
    expect(result.current).toMatchObject({ data: 'B', fetching: false });
    expect(r.fn).not.toHaveBeenCalled();
    // A key never read: loading.
    rerender({ parts: ['dir', '/c'], fn: r.fn, opts });
    await flush();
    expect(result.current).toMatchObject({ data: undefined, loading: true });
    expect(r.fn).toHaveBeenCalledTimes(1);
    // Back to /a after its answer went stale: shown at once, read again.
    await flush(60_000);
    rerender({ parts: ['dir', '/a'], fn: r.fn, opts });
    await flush();
    expect(result.current).toMatchObject({ data: 'A', loading: false, fetching: true });
    expect(r.fn).toHaveBeenCalledTimes(2);
    r.calls[1]!.resolve('A2');
    await flush();
    expect(result.current.data).toBe('A2');
  });

  it('invalidate reads again only the entries being watched; the others are read when next asked', async () => {
    const q = new MachineQueries('m');
    const opts = { staleTimeMs: 60_000 };
    const shown = vi.fn(async () => 'shown');
    const off = vi.fn(async () => 'off');
    const idle = vi.fn(async () => 'idle');
    const settings = vi.fn(async () => 'settings');
    await q.fetch(['files', '/off'], off);
    await q.fetch(['files', '/idle'], idle);
    await q.fetch(['settings'], settings);
    watch(q, { parts: ['files', '/shown'], fn: shown, opts });
    watch(q, { parts: ['files', '/off'], fn: off, opts: { ...opts, enabled: false } });
    await flush();
    expect([shown, off, idle, settings].map((f) => f.mock.calls.length)).toEqual([1, 1, 1, 1]);
    await act(() => q.invalidate(['files']));
    expect([shown, off, idle, settings].map((f) => f.mock.calls.length)).toEqual([2, 1, 1, 1]);
    // Not shown, but stale now, however fresh by age; outside the prefix: untouched.
    await q.fetch(['files', '/idle'], idle, opts);
    await q.fetch(['settings'], settings, opts);
    expect([idle, settings].map((f) => f.mock.calls.length)).toEqual([2, 1]);
  });

  it('invalidating shown data with a read in flight starts the read again (the old request aborted)', async () => {
    const q = new MachineQueries('m');
    const r = controlled<string>();
    const { result } = watch(q, { parts: ['k'], fn: r.fn, opts: { staleTimeMs: 60_000 } });
    await flush();
    r.calls[0]!.resolve('v1');
    await flush();
    act(() => result.current.refetch());
    const joined = q.fetch(['k'], r.fn, { staleTimeMs: 0 });
    expect(r.fn).toHaveBeenCalledTimes(2);
    const done = q.invalidate();
    expect(r.calls[1]!.signal.aborted).toBe(true);
    expect(r.fn).toHaveBeenCalledTimes(3);
    r.calls[1]!.resolve('before the command');
    r.calls[2]!.resolve('after the command');
    await act(() => done);
    expect(result.current.data).toBe('after the command');
    expect(await joined).toBe('after the command'); // its caller gets the new read's answer
  });

  it('refetchIntervalMs reads again while watched, and stops when nothing watches', async () => {
    const q = new MachineQueries('m');
    let n = 0;
    const fn = vi.fn(async () => ++n);
    const view = watch(q, { parts: ['k'], fn, opts: { staleTimeMs: 60_000, refetchIntervalMs: 1000 } });
    await flush();
    expect(fn).toHaveBeenCalledTimes(1);
    await flush(1000);
    expect(fn).toHaveBeenCalledTimes(2);
    await flush(1000);
    expect(fn).toHaveBeenCalledTimes(3);
    expect(view.result.current.data).toBe(3);
    view.unmount();
    await flush(10_000);
    expect(fn).toHaveBeenCalledTimes(3);
  });

  it('enabled: false waits (a cached answer is still shown); enabled, a stale key is read', async () => {
    const q = new MachineQueries('m');
    const fn = vi.fn(async () => 'x');
    const { result, rerender } = watch(q, { parts: ['k'], fn, opts: { staleTimeMs: 1000, enabled: false } });
    await flush(5000);
    expect(fn).not.toHaveBeenCalled();
    expect(result.current).toMatchObject({ data: undefined, loading: false, fetching: false });
    await act(() => q.invalidate());
    expect(fn).not.toHaveBeenCalled();
    q.set(['k'], 'cached');
    await flush();
    expect(result.current.data).toBe('cached');
    await flush(1000);
    rerender({ parts: ['k'], fn, opts: { staleTimeMs: 1000, enabled: true } });
    await flush();
    expect(fn).toHaveBeenCalledTimes(1);
    expect(result.current.data).toBe('x');
  });

  it('the last view leaving a key cancels its read in flight: aborted, nothing written', async () => {
    const q = new MachineQueries('m');
    const r = controlled<string>();
    const view = watch(q, { parts: ['k'], fn: r.fn, opts: { staleTimeMs: 60_000 } });
    await flush();
    expect(r.calls).toHaveLength(1);
    view.unmount();
    expect(r.calls[0]!.signal.aborted).toBe(true);
    r.calls[0]!.resolve('late');
    await flush();
    expect(q.peek(['k'])).toBeUndefined();
  });

  it('gives one view object per state: a re-render without a change gets the same object', async () => {
    const q = new MachineQueries('m');
    let renders = 0;
    const fn = async () => ({ list: ['a'] });
    const { result, rerender } = renderHook(
      (p: { tick: number }) => {
        renders++;
        return { view: useMachineQuery(q, ['k'], fn, { staleTimeMs: 0 }), tick: p.tick };
      },
      { initialProps: { tick: 0 } },
    );
    await flush();
    const settled = result.current.view;
    expect(settled.data).toEqual({ list: ['a'] });
    const count = renders;
    rerender({ tick: 1 });
    rerender({ tick: 2 });
    await flush(1000);
    expect(result.current.view).toBe(settled);
    expect(renders).toBe(count + 2); // the two re-renders asked for, no loop
    // A refetch with an equal answer: the same data object is shown.
    await act(async () => {
      settled.refetch();
      await vi.advanceTimersByTimeAsync(0);
    });
    expect(result.current.view.data).toBe(settled.data);
  });
});
