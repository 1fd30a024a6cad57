// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { createContext } from '../fleet';
import { alwaysVisible } from '../link';
import type { MachineInfo } from '../types';
import { MachineQueries, useMachineQuery } from './query';

const info: MachineInfo = { id: 'q1', name: 'Q1', kind: 'duet', simulated: false };

afterEach(cleanup);

const flush = () => act(async () => new Promise((r) => setTimeout(r, 0)));

describe('MachineQueries', () => {
  it('shares one request per key, keeps answers fresh for their stale time, keys per machine', async () => {
    const a = new MachineQueries('a');
    const b = new MachineQueries('b');
    const fn = vi.fn(async () => ['x.gcode']);
    const [r1, r2] = await Promise.all([
      a.fetch(['files', '/gcodes'], fn, { staleTimeMs: 10_000 }),
      a.fetch(['files', '/gcodes'], fn, { staleTimeMs: 10_000 }),
    ]);
    expect(r1).toEqual(['x.gcode']);
    expect(r2).toBe(r1);
    expect(fn).toHaveBeenCalledTimes(1);
    await a.fetch(['files', '/gcodes'], fn, { staleTimeMs: 10_000 });
    expect(fn).toHaveBeenCalledTimes(1); // fresh: from cache
    expect(b.peek(['files', '/gcodes'])).toBeUndefined(); // another machine's cache is its own
    await a.invalidate(['files']);
    await a.fetch(['files', '/gcodes'], fn, { staleTimeMs: 10_000 });
    expect(fn).toHaveBeenCalledTimes(2);
  });

  it('is bounded: beyond maxEntries the least recently read unobserved entries go', async () => {
    const q = new MachineQueries('m', { maxEntries: 3 });
    for (let i = 0; i < 6; i++) await q.fetch(['thumb', i], async () => `png${i}`);
    expect(q.size).toBe(3);
    expect(q.peek(['thumb', 0])).toBeUndefined();
    expect(q.peek(['thumb', 5])).toBe('png5');
  });

  it('clear() cancels a read in flight: its signal is aborted and nothing is cached', async () => {
    const q = new MachineQueries('m');
    let signal: AbortSignal | null = null;
    const pending = q.fetch(['files'], (s) => {
      signal = s;
      return new Promise<string[]>((_, reject) =>
        s.addEventListener('abort', () => reject(new Error('aborted'))),
      );
    });
    q.clear();
    await expect(pending).rejects.toBeTruthy();
    expect((signal as AbortSignal | null)?.aborted).toBe(true);
    expect(q.size).toBe(0);
  });
});

describe('useMachineQuery and command invalidation', () => {
  it('shows the read, and refetches it after a command that declares it stale', async () => {
    const ctx = createContext(info, {
      visibility: alwaysVisible,
      principal: () => ({ name: 'op', role: 'supervisor' }),
    });
    ctx.snapshot.setState({ link: 'online' });
    let files = ['a.gcode'];
    const list = vi.fn(async () => [...files]);
    function Files() {
      const q = useMachineQuery(ctx.queries, ['files', '/gcodes'], list, { staleTimeMs: 60_000 });
      return <p>{q.loading ? 'loading' : (q.data ?? []).join(',')}</p>;
    }
    render(<Files />);
    await flush();
    expect(screen.getByText('a.gcode')).toBeTruthy();
    expect(list).toHaveBeenCalledTimes(1);
    files = ['a.gcode', 'b.gcode'];
    await act(async () => {
      await ctx.commands.run(
        {
          id: 'duet.upload',
          label: 'Upload',
          hazard: 'adjust',
          role: 'operator',
          invalidates: [['files']],
          perform: async () => 'uploaded',
        },
        undefined,
      );
    });
    await flush();
    expect(list).toHaveBeenCalledTimes(2);
    expect(screen.getByText('a.gcode,b.gcode')).toBeTruthy();
  });
});

describe('useMachineQuery across machines', () => {
  it("re-rendered with another machine's cache shows that machine's read, and leaves the first machine's cache alone", async () => {
    const a = new MachineQueries('a');
    const b = new MachineQueries('b');
    const readA = vi.fn(async () => 'files of A');
    const readB = vi.fn(async () => 'files of B');
    function Files(props: { id: string; queries: MachineQueries; read: () => Promise<string> }) {
      const q = useMachineQuery(props.queries, ['files'], props.read, { staleTimeMs: 60_000 });
      return <p data-testid={props.id}>{q.loading ? 'loading' : (q.data ?? 'none')}</p>;
    }
    // Two views of A's files; the second is then shown for machine B.
    const both = (second: { queries: MachineQueries; read: () => Promise<string> }) => (
      <>
        <Files id="stays" queries={a} read={readA} />
        <Files id="moves" {...second} />
      </>
    );
    const { rerender } = render(both({ queries: a, read: readA }));
    await flush();
    expect(screen.getByTestId('moves').textContent).toBe('files of A');
    rerender(both({ queries: b, read: readB }));
    await flush();
    expect(screen.getByTestId('moves').textContent).toBe('files of B');
    expect(readB).toHaveBeenCalledTimes(1);
    expect(b.peek(['files'])).toBe('files of B');
    expect(a.peek(['files'])).toBe('files of A');
    // A's read, read again, is read with A's fetcher (B's was never written into A's cache).
    await act(() => a.invalidate(['files']));
    await flush();
    expect(readA).toHaveBeenCalledTimes(2);
    expect(readB).toHaveBeenCalledTimes(1);
    expect(screen.getByTestId('stays').textContent).toBe('files of A');
  });
});
