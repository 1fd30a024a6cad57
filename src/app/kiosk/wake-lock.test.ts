import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { ScreenWakeLock, WAKE_RETRY_MS, type SentinelLike, type WakeEnv } from './wake-lock';

/** A fake `navigator.wakeLock`: records requests; the test decides how each one ends. */
class FakeWakeLock {
  requests: Array<{ resolve: (s: FakeSentinel) => void; reject: (e: Error) => void }> = [];
  sentinels: FakeSentinel[] = [];
  request(type: 'screen'): Promise<SentinelLike> {
    expect(type).toBe('screen');
    return new Promise<FakeSentinel>((resolve, reject) => this.requests.push({ resolve, reject }));
  }
  /** Grants the oldest request still open. */
  grant(): FakeSentinel {
    const r = this.requests.shift();
    if (!r) throw new Error('no request to grant');
    const s = new FakeSentinel();
    this.sentinels.push(s);
    r.resolve(s);
    return s;
  }
  refuse(): void {
    const r = this.requests.shift();
    if (!r) throw new Error('no request to refuse');
    r.reject(new DOMException('denied', 'NotAllowedError'));
  }
  get held(): number {
    return this.sentinels.filter((s) => !s.released).length;
  }
}

class FakeSentinel extends EventTarget implements SentinelLike {
  released = false;
  release(): Promise<void> {
    if (!this.released) {
      this.released = true;
      this.dispatchEvent(new Event('release'));
    }
    return Promise.resolve();
  }
  /** The browser drops it (page hidden). */
  drop(): void {
    void this.release();
  }
}

class FakeDocument extends EventTarget {
  visibilityState: DocumentVisibilityState = 'visible';
  show(state: DocumentVisibilityState): void {
    this.visibilityState = state;
    this.dispatchEvent(new Event('visibilitychange'));
  }
}

let api: FakeWakeLock;
let doc: FakeDocument;
const env = (over: Partial<WakeEnv> = {}): WakeEnv => ({ wakeLock: api, secure: true, doc, ...over });
/** Lets promise callbacks run. */
const settle = () => vi.advanceTimersByTimeAsync(0);

beforeEach(() => {
  vi.useFakeTimers();
  api = new FakeWakeLock();
  doc = new FakeDocument();
});
afterEach(() => {
  vi.useRealTimers();
});

describe('ScreenWakeLock', () => {
  it('asks for the screen lock when a job runs and releases it when the job ends', async () => {
    const lock = new ScreenWakeLock(env());
    lock.start();
    expect(lock.status).toBe('off');
    expect(api.requests).toHaveLength(0);
    lock.want(true);
    expect(api.requests).toHaveLength(1);
    expect(lock.status).toBe('waiting');
    api.grant();
    await settle();
    expect(lock.status).toBe('held');
    expect(api.held).toBe(1);
    lock.want(false);
    expect(api.held).toBe(0);
    expect(lock.status).toBe('off');
  });

  it('asks again when the page shows after the browser dropped the lock on hiding it', async () => {
    const lock = new ScreenWakeLock(env());
    lock.start();
    lock.want(true);
    const first = api.grant();
    await settle();
    doc.show('hidden');
    first.drop();
    expect(lock.status).toBe('waiting');
    // Hidden: nothing is asked for (the browser would refuse).
    expect(api.requests).toHaveLength(0);
    doc.show('visible');
    expect(api.requests).toHaveLength(1);
    api.grant();
    await settle();
    expect(lock.status).toBe('held');
    expect(api.held).toBe(1);
  });

  it('a job starting while the page is hidden waits for it to show', async () => {
    doc.visibilityState = 'hidden';
    const lock = new ScreenWakeLock(env());
    lock.start();
    lock.want(true);
    expect(api.requests).toHaveLength(0);
    expect(lock.status).toBe('waiting');
    doc.show('visible');
    api.grant();
    await settle();
    expect(lock.status).toBe('held');
  });

  it('a refused request is tried again later while the job runs, not after it ended', async () => {
    const lock = new ScreenWakeLock(env());
    lock.start();
    lock.want(true);
    api.refuse();
    await settle();
    expect(lock.status).toBe('refused');
    await vi.advanceTimersByTimeAsync(WAKE_RETRY_MS - 1);
    expect(api.requests).toHaveLength(0);
    await vi.advanceTimersByTimeAsync(1);
    expect(api.requests).toHaveLength(1);
    api.refuse();
    await settle();
    lock.want(false);
    await vi.advanceTimersByTimeAsync(WAKE_RETRY_MS * 3);
    expect(api.requests).toHaveLength(0);
    expect(lock.status).toBe('off');
  });

  it('a lock granted after the job ended is released at once', async () => {
    const lock = new ScreenWakeLock(env());
    lock.start();
    lock.want(true);
    lock.want(false);
    const late = api.grant();
    await settle();
    expect(late.released).toBe(true);
    expect(lock.status).toBe('off');
  });

  it('the page going releases the lock and stops listening to visibility', async () => {
    const lock = new ScreenWakeLock(env());
    lock.start();
    lock.want(true);
    api.grant();
    await settle();
    lock.stop();
    expect(api.held).toBe(0);
    doc.show('hidden');
    doc.show('visible');
    expect(api.requests).toHaveLength(0);
    // Not started: a want is ignored.
    lock.want(true);
    expect(api.requests).toHaveLength(0);
  });

  it('says why it cannot keep the screen on: no API, or not a secure context', () => {
    const none = new ScreenWakeLock(env({ wakeLock: undefined }));
    none.start();
    none.want(true);
    expect(none.status).toBe('unsupported');
    const http = new ScreenWakeLock(env({ secure: false }));
    http.start();
    http.want(true);
    expect(http.status).toBe('insecure');
    expect(api.requests).toHaveLength(0);
  });

  it('tells subscribers when the status changes', async () => {
    const lock = new ScreenWakeLock(env());
    const seen: string[] = [];
    lock.subscribe(() => seen.push(lock.status));
    lock.start();
    lock.want(true);
    api.grant();
    await settle();
    lock.want(false);
    expect(seen).toEqual(['waiting', 'held', 'off']);
  });
});
