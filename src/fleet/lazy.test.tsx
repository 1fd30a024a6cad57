// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { Suspense } from 'react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { lazyView, preloadViews } from './lazy';

function Hello({ who }: { who: string }) {
  return <p>hello {who}</p>;
}

const shown = (View: ReturnType<typeof lazyView<{ Hello: typeof Hello }, 'Hello'>>) =>
  render(
    <Suspense fallback={<p>loading</p>}>
      <View who="tablet" />
    </Suspense>,
  );

describe('lazyView', () => {
  afterEach(cleanup);

  it('shows the fallback while the code loads, then the view; loads once', async () => {
    const load = vi.fn(() => Promise.resolve({ Hello }));
    const View = lazyView(load, 'Hello');
    shown(View);
    expect(screen.getByText('loading')).toBeTruthy();
    await act(async () => {
      await Promise.resolve();
    });
    expect(await screen.findByText('hello tablet')).toBeTruthy();
    await View.preload();
    expect(load).toHaveBeenCalledTimes(1);
  });

  it('renders a preloaded view at once, without its fallback', async () => {
    const View = lazyView(() => Promise.resolve({ Hello }), 'Hello');
    preloadViews([View]);
    await View.preload();
    shown(View);
    // The first commit already holds the view: no fallback (React would keep one for 300 ms).
    expect(screen.queryByText('loading')).toBeNull();
    expect(screen.getByText('hello tablet')).toBeTruthy();
  });

  it('tries a failed load again on the next preload', async () => {
    let calls = 0;
    const View = lazyView(
      () => (++calls === 1 ? Promise.reject(new Error('offline')) : Promise.resolve({ Hello })),
      'Hello',
    );
    await expect(View.preload()).rejects.toThrow('offline');
    await expect(View.preload()).resolves.toEqual({ Hello });
    expect(calls).toBe(2);
  });
});
