// @vitest-environment happy-dom
import { act, render } from '@testing-library/react';
import { useStore } from 'zustand';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { createStore } from 'zustand/vanilla';
import { createContext } from '../fleet';
import { alwaysVisible, Poller } from '../link';
import type { MachineInfo } from '../types';
import { defineCommands } from './commands';
import { Lifecycle } from './lifecycle';
import { KernelSession } from './session';
import { createSharedStore } from './share';

const info: MachineInfo = { id: 'k1', name: 'K1', kind: 'xtool', simulated: false };

beforeEach(() => {
  vi.useFakeTimers();
});
afterEach(() => {
  vi.useRealTimers();
});

function deferred<T>() {
  let resolve!: (v: T) => void;
  let reject!: (e: Error) => void;
  const promise = new Promise<T>((res, rej) => {
    resolve = res;
    reject = rej;
  });
  return { promise, resolve, reject };
}

describe('Lifecycle', () => {
  it('clears every timer on stop, and a guarded callback of an old run never runs', async () => {
    const life = new Lifecycle();
    life.start();
    const fired: string[] = [];
    life.setTimeout(() => fired.push('timeout'), 100);
    life.setInterval(() => fired.push('interval'), 50);
    const late = life.guard(() => fired.push('late'));
    expect(life.timerCount).toBe(2);
    life.stop();
    expect(life.timerCount).toBe(0);
    expect(life.signal.aborted).toBe(true);
    await vi.advanceTimersByTimeAsync(1000);
    life.start(); // a new run: the old run's callback still must not write
    late();
    expect(fired).toEqual([]);
    expect(life.setTimeout(() => undefined, 1)).not.toBeNull();
    life.stop();
    expect(life.setTimeout(() => fired.push('after'), 1)).toBeNull();
    await vi.advanceTimersByTimeAsync(10);
    expect(fired).toEqual([]);
  });

  it('runs stop cleanups newest first, once', () => {
    const life = new Lifecycle();
    const order: number[] = [];
    life.start();
    life.onStop(() => order.push(1));
    life.onStop(() => order.push(2));
    life.stop();
    life.stop();
    expect(order).toEqual([2, 1]);
  });
});

class TestSession extends KernelSession {
  readonly store = createSharedStore(() => ({ value: 0, reads: 0 }));
  readonly commands = {};
  readonly answers: Array<ReturnType<typeof deferred<number>>> = [];
  readonly signals: AbortSignal[] = [];
  readonly poller = this.poll<number>({
    name: 'value',
    read: (signal) => {
      this.signals.push(signal);
      const d = deferred<number>();
      // Like fetch: an aborted request rejects (the answer may still come for the test).
      signal.addEventListener('abort', () => d.reject(new Error('aborted')));
      this.answers.push(d);
      this.store.setState((s) => ({ reads: s.reads + 1 }));
      return d.promise;
    },
    apply: (value) => this.store.setState({ value }),
    intervalMs: () => 1000,
  });
}

describe('KernelSession', () => {
  it('writes nothing after stop: an answer to a poll in flight is dropped, its request aborted', async () => {
    const s = new TestSession(createContext(info, { visibility: alwaysVisible }));
    s.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(s.answers).toHaveLength(1);
    s.stop();
    expect(s.signals[0]?.aborted).toBe(true);
    s.answers[0]?.resolve(42);
    await vi.advanceTimersByTimeAsync(5000);
    expect(s.store.getState().value).toBe(0);
    expect(s.answers).toHaveLength(1); // no poll after stop
  });

  it('drops the answer of a previous run after stop and a new start', async () => {
    const s = new TestSession(createContext(info, { visibility: alwaysVisible }));
    s.start();
    await vi.advanceTimersByTimeAsync(0);
    s.stop();
    s.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(s.answers).toHaveLength(2);
    s.answers[0]?.resolve(1); // late answer of the first run
    s.answers[1]?.resolve(2);
    await vi.advanceTimersByTimeAsync(0);
    expect(s.store.getState().value).toBe(2);
    s.answers[0]?.resolve(1);
    await vi.advanceTimersByTimeAsync(0);
    expect(s.store.getState().value).toBe(2);
    s.stop();
  });

  it('does not mark the link failed for a poll cancelled by stop', async () => {
    const ctx = createContext(info, { visibility: alwaysVisible });
    class Failing extends KernelSession {
      readonly commands = {};
      reject: ((e: Error) => void) | null = null;
      readonly p = this.poll<number>({
        name: 'x',
        read: () => new Promise<number>((_, reject) => (this.reject = reject)),
        apply: () => undefined,
        intervalMs: () => 1000,
      });
    }
    const s = new Failing(ctx);
    s.start();
    await vi.advanceTimersByTimeAsync(0);
    s.stop();
    s.reject?.(new Error('aborted'));
    await vi.advanceTimersByTimeAsync(0);
    expect(ctx.snapshot.getState().link).toBe('connecting');
    expect(ctx.log.store.getState().entries.some((e) => e.source === 'link')).toBe(false);
  });
});

describe('Poller.kick (issue 12, defect 4)', () => {
  it('polls again right after the poll in flight when kicked during it, not an interval later', async () => {
    const answers: Array<() => void> = [];
    const poller = new Poller({
      run: () => new Promise<void>((r) => answers.push(r)),
      intervalMs: () => 10_000,
      visibility: alwaysVisible,
    });
    poller.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(poller.started).toBe(1);
    poller.kick(); // a command was sent while the poll was on its way
    answers[0]?.();
    await vi.advanceTimersByTimeAsync(0);
    expect(poller.started).toBe(2);
    // One kick, one extra poll: then the interval again.
    answers[1]?.();
    await vi.advanceTimersByTimeAsync(9_999);
    expect(poller.started).toBe(2);
    await vi.advanceTimersByTimeAsync(1);
    expect(poller.started).toBe(3);
    poller.stop();
  });
});

describe('structural sharing', () => {
  it('keeps the identity of equal parts, and an equal write notifies nobody', () => {
    const store = createSharedStore(() => ({ a: { x: [1, 2], y: 'y' }, b: { n: 1 } }));
    const before = store.getState();
    const listener = vi.fn();
    store.subscribe(listener);
    store.setState({ a: { x: [1, 2], y: 'y' }, b: { n: 1 } });
    expect(store.getState()).toBe(before);
    expect(listener).not.toHaveBeenCalled();
    store.setState({ a: { x: [1, 2], y: 'y' }, b: { n: 2 } });
    expect(store.getState().a).toBe(before.a);
    expect(store.getState().b).not.toBe(before.b);
    expect(listener).toHaveBeenCalledTimes(1);
  });

  it('the machine snapshot shares too: a component on an unchanged part does not re-render', () => {
    const ctx = createContext(info, { visibility: alwaysVisible });
    let renders = 0;
    function Alarms() {
      renders++;
      const alarms = useStore(ctx.snapshot, (s) => s.alarms);
      return <span>{alarms.length}</span>;
    }
    render(<Alarms />);
    expect(renders).toBe(1);
    act(() => {
      // A new frame: the same alarms (new objects), a new position.
      ctx.snapshot.setState({ alarms: [], activityLabel: 'Running 10 %' });
    });
    act(() => {
      ctx.snapshot.setState({
        alarms: [{ id: 'a', severity: 'warning', message: 'lid', since: 1, blocking: false }],
      });
    });
    expect(renders).toBe(2);
    act(() => {
      ctx.snapshot.setState({
        alarms: [{ id: 'a', severity: 'warning', message: 'lid', since: 1, blocking: false }],
        activityLabel: 'Running 11 %',
      });
    });
    expect(renders).toBe(2);
  });
});

describe('defineCommands', () => {
  it('availability reads only the named stores, and every command lists them', () => {
    const ctx = createContext(info, { visibility: alwaysVisible });
    const family = createStore(() => ({ lidOpen: false }));
    const cmds = defineCommands({ snapshot: ctx.snapshot, family });
    const frame = cmds.define({
      id: 'k.frame',
      label: 'Frame',
      hazard: 'motion',
      role: 'operator',
      available: ({ family: f }) => (f.lidOpen ? 'The lid is open' : true),
      perform: async () => 'framed',
    });
    expect(frame.needs).toEqual([ctx.snapshot, family]);
    expect(cmds.all['k.frame']).toBe(frame);
    expect(frame.available?.(ctx.snapshot.getState())).toBe(true);
    family.setState({ lidOpen: true });
    expect(frame.available?.(ctx.snapshot.getState())).toBe('The lid is open');
    expect(() => cmds.define({ ...frame, available: undefined })).toThrow(/twice/);
  });
});
