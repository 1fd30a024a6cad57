// @vitest-environment happy-dom
import { cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { createStore } from 'zustand/vanilla';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import type { ScreenshotState } from '../feeds';
import type { TouchcutSession } from '../session';
import { ScreenThumbnail, ScreenView } from './ScreenView';

afterEach(() => cleanup());

/** A session stand-in whose screenshot feed holds `blob` (as if the controller had sent it). */
function withScreenshot(blob: Blob): TouchcutSession {
  const ctx = createContext(
    { id: 'tcs', name: 'Plasma', kind: 'touchcut', simulated: false },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'viewer' }) },
  );
  ctx.snapshot.setState({ link: 'online' });
  const store = createStore<ScreenshotState>(() => ({ blob, at: Date.now(), error: null, loading: false }));
  const stub = { ctx, machine: ctx.machine, screenshot: { store, subscribe: () => () => undefined } };
  return stub as unknown as TouchcutSession;
}

const PNG = new Uint8Array([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]);

describe('TouchCut screenshots become blob: URLs only as raster images', () => {
  it('shows a PNG screenshot', () => {
    render(<ScreenView session={withScreenshot(new Blob([PNG], { type: 'image/png' }))} />);
    expect(screen.getByTestId('screen-image').getAttribute('src')).toMatch(/^blob:/);
  });

  it.each([
    ['text/html', '<script>parent.fetch("/machines/acc-laser/system?action=stop")</script>'],
    ['image/svg+xml', '<svg xmlns="http://www.w3.org/2000/svg" onload="alert(1)"/>'],
    ['application/xhtml+xml', '<html xmlns="http://www.w3.org/1999/xhtml"><script>alert(1)</script></html>'],
    ['', '<script>alert(1)</script>'],
  ])(
    'never makes a blob: URL of a %j "screenshot" (it would run in our origin in a new tab)',
    (type, body) => {
      const session = withScreenshot(new Blob([body], { type }));
      render(<ScreenView session={session} />);
      expect(screen.queryByTestId('screen-image')).toBeNull();
      expect(document.querySelector('img')).toBeNull();
      cleanup();
      render(<ScreenThumbnail session={session} />);
      expect(document.querySelector('img')).toBeNull();
    },
  );

  it('the fleet thumbnail shows a PNG', () => {
    render(<ScreenThumbnail session={withScreenshot(new Blob([PNG], { type: 'image/png' }))} />);
    expect(document.querySelector('img')?.getAttribute('src')).toMatch(/^blob:/);
  });
});
