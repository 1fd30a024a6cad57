// @vitest-environment happy-dom
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { RegisterSWOptions } from 'virtual:pwa-register';
import { pwaWanted } from './wanted';

import { IDLE_MS, pageBusy, reloadWhenIdle, startPwa, UPDATE_CHECK_MS } from './updates';

const registerSW = vi.fn<(o: RegisterSWOptions) => unknown>();

describe('when the page registers the service worker', () => {
  it('only in a production build, in a secure context, with service workers', () => {
    const all = { production: true, secureContext: true, serviceWorker: true };
    expect(pwaWanted(all)).toBe(true);
    expect(pwaWanted({ ...all, production: false })).toBe(false);
    expect(pwaWanted({ ...all, secureContext: false })).toBe(false);
    expect(pwaWanted({ ...all, serviceWorker: false })).toBe(false);
  });

  it('not in the unit tests’ page (not a production build)', () => {
    expect(pwaWanted()).toBe(false);
  });
});

describe('updates', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    document.body.innerHTML = '';
  });
  afterEach(() => {
    vi.useRealTimers();
    registerSW.mockClear();
  });

  it('registers, asks for a new version every hour, and reloads when idle once it took over', () => {
    startPwa(registerSW);
    expect(registerSW).toHaveBeenCalledTimes(1);
    const options = registerSW.mock.calls[0]?.[0];
    const update = vi.fn(() => Promise.resolve());
    options?.onRegisteredSW?.('/sw.js', { installing: null, update } as unknown as ServiceWorkerRegistration);
    vi.advanceTimersByTime(UPDATE_CHECK_MS - 1);
    expect(update).not.toHaveBeenCalled();
    vi.advanceTimersByTime(1);
    expect(update).toHaveBeenCalledTimes(1);
    // The page would reload at once without onNeedReload: it must be there.
    expect(typeof options?.onNeedReload).toBe('function');
  });

  it('reloads after IDLE_MS without input, not while someone taps', () => {
    const reload = vi.fn();
    reloadWhenIdle(reload, document);
    vi.advanceTimersByTime(IDLE_MS - 5_000);
    document.dispatchEvent(new Event('pointerdown'));
    vi.advanceTimersByTime(IDLE_MS - 5_000);
    expect(reload).not.toHaveBeenCalled();
    vi.advanceTimersByTime(10_000);
    expect(reload).toHaveBeenCalledTimes(1);
    vi.advanceTimersByTime(IDLE_MS * 4);
    expect(reload).toHaveBeenCalledTimes(1);
  });

  it('waits while a dialog is open or a command is in flight', () => {
    const reload = vi.fn();
    document.body.innerHTML = '<div role="dialog" aria-label="Stop the job?"></div>';
    reloadWhenIdle(reload, document);
    vi.advanceTimersByTime(IDLE_MS * 3);
    expect(reload).not.toHaveBeenCalled();
    document.body.innerHTML = '<button aria-busy="true">Pause</button>';
    vi.advanceTimersByTime(IDLE_MS * 3);
    expect(reload).not.toHaveBeenCalled();
    document.body.innerHTML = '';
    vi.advanceTimersByTime(5_000);
    expect(reload).toHaveBeenCalledTimes(1);
  });

  it('can be cancelled', () => {
    const reload = vi.fn();
    const cancel = reloadWhenIdle(reload, document);
    cancel();
    vi.advanceTimersByTime(IDLE_MS * 3);
    expect(reload).not.toHaveBeenCalled();
  });
});

describe('pageBusy', () => {
  it('is true with a half-typed field focused, false with an empty one', () => {
    document.body.innerHTML = '<label>MDI <input id="mdi"></label>';
    const input = document.getElementById('mdi') as HTMLInputElement;
    input.focus();
    expect(pageBusy(document)).toBe(false);
    input.value = 'G0 X10';
    expect(pageBusy(document)).toBe(true);
    input.blur();
    expect(pageBusy(document)).toBe(false);
  });
});
