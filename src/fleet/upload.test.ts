import { describe, expect, it } from 'vitest';
import { LinkError } from './errors';
import { UploadBusy, UploadTracker, uploadActive, type UploadState } from './upload';

function phases(t: UploadTracker): UploadState['phase'][] {
  const seen: UploadState['phase'][] = [t.state.phase];
  t.store.subscribe((s) => seen.push(s.phase));
  return seen;
}

function deferred<T>() {
  let resolve!: (v: T) => void;
  let reject!: (e: unknown) => void;
  const promise = new Promise<T>((res, rej) => {
    resolve = res;
    reject = rej;
  });
  return { promise, resolve, reject };
}

describe('UploadTracker: transitions', () => {
  it('idle → uploading (progress) → verifying → done', () => {
    const t = new UploadTracker();
    const seen = phases(t);
    expect(t.state).toEqual({ phase: 'idle' });
    const h = t.start({ name: 'part.gcode', total: 1000, target: '/tmp.gcode' });
    expect(t.state).toEqual({
      phase: 'uploading',
      name: 'part.gcode',
      target: '/tmp.gcode',
      loaded: 0,
      total: 1000,
    });
    expect(uploadActive(t.state)).toBe(true);
    h.progress({ loaded: 400, total: 1000 });
    expect(t.state).toMatchObject({ phase: 'uploading', loaded: 400, total: 1000 });
    // A progress event without a length keeps the known total.
    h.progress({ loaded: 500, total: 0 });
    expect(t.state).toMatchObject({ loaded: 500, total: 1000 });
    h.verifying();
    expect(t.state).toMatchObject({ phase: 'verifying', loaded: 1000 });
    // Late progress of the finished transfer does not go back to uploading.
    h.progress({ loaded: 10, total: 1000 });
    expect(t.state.phase).toBe('verifying');
    h.done('part.gcode is on the laser.');
    expect(t.state).toEqual({
      phase: 'done',
      name: 'part.gcode',
      target: '/tmp.gcode',
      loaded: 1000,
      total: 1000,
      message: 'part.gcode is on the laser.',
    });
    expect(uploadActive(t.state)).toBe(false);
    expect(seen).toEqual(['idle', 'uploading', 'uploading', 'uploading', 'verifying', 'done']);
  });

  it('uploading → done without verification', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 3 });
    h.done();
    expect(t.state).toMatchObject({ phase: 'done', target: null, loaded: 3, message: null });
  });

  it('failed carries the error in words', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 3 });
    h.fail(new LinkError('http', 'HTTP 507 from upload: disk full'));
    expect(t.state).toMatchObject({ phase: 'failed', message: 'HTTP 507 from upload: disk full' });
    // Nothing after the end moves it.
    h.done('late');
    h.progress({ loaded: 3, total: 3 });
    expect(t.state).toMatchObject({ phase: 'failed', loaded: 0 });
  });

  it('a verification that fails is a failed upload', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 3 });
    h.verifying();
    h.fail(new Error('The laser answered "ok" but a.g is not on the SD card'));
    expect(t.state).toMatchObject({
      phase: 'failed',
      message: expect.stringContaining('not on the SD card'),
    });
  });

  it('an aborted transfer ends as cancelled, not failed (LinkError or DOM AbortError)', () => {
    const t = new UploadTracker();
    t.start({ name: 'a', total: 1 }).fail(new LinkError('aborted', 'Upload cancelled'));
    expect(t.state.phase).toBe('cancelled');
    t.start({ name: 'b', total: 1 }).fail(new DOMException('The user aborted a request.', 'AbortError'));
    expect(t.state.phase).toBe('cancelled');
  });

  it('cancel fires the signal and is cancelled at once; what the transfer says afterwards is ignored', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 10 });
    h.progress({ loaded: 4, total: 10 });
    expect(h.signal.aborted).toBe(false);
    expect(t.cancel()).toBe(true);
    expect(h.signal.aborted).toBe(true);
    expect(t.state).toMatchObject({ phase: 'cancelled', name: 'a.g', loaded: 4 });
    h.fail(new LinkError('network', 'Upload failed: cannot reach the controller'));
    h.done('ok');
    expect(t.state.phase).toBe('cancelled');
    expect(t.cancel()).toBe(false);
  });

  it('verification is not cancelled (the file is already on the controller)', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 10 });
    h.verifying();
    expect(t.cancel()).toBe(false);
    expect(h.signal.aborted).toBe(false);
    expect(t.state.phase).toBe('verifying');
  });

  it('one upload at a time; a new one after the end, and the old handle cannot touch it', () => {
    const t = new UploadTracker();
    const first = t.start({ name: 'a.g', total: 10 });
    expect(() => t.start({ name: 'b.g', total: 5 })).toThrow(UploadBusy);
    first.verifying();
    expect(() => t.start({ name: 'b.g', total: 5 })).toThrow('An upload (a.g) is still running');
    first.done();
    const second = t.start({ name: 'b.g', total: 5 });
    first.fail(new Error('stale'));
    first.progress({ loaded: 1, total: 10 });
    expect(t.state).toMatchObject({ phase: 'uploading', name: 'b.g', loaded: 0, total: 5 });
    second.done();
    expect(t.state).toMatchObject({ phase: 'done', name: 'b.g' });
  });

  it('reset forgets a finished upload, never a running one', () => {
    const t = new UploadTracker();
    const h = t.start({ name: 'a.g', total: 1 });
    t.reset();
    expect(t.state.phase).toBe('uploading');
    h.done();
    t.reset();
    expect(t.state).toEqual({ phase: 'idle' });
  });
});

describe('UploadTracker.run', () => {
  it('passes signal and progress to the work, and ends done with a string result', async () => {
    const t = new UploadTracker();
    const seen = phases(t);
    const r = await t.run({ name: 'a.g', total: 4 }, async (h) => {
      expect(h.signal.aborted).toBe(false);
      h.progress({ loaded: 2, total: 4 });
      h.progress({ loaded: 4, total: 4 });
      h.verifying();
      return 'a.g uploaded and checked';
    });
    expect(r).toBe('a.g uploaded and checked');
    expect(t.state).toMatchObject({ phase: 'done', message: 'a.g uploaded and checked', loaded: 4 });
    expect(seen).toEqual(['idle', 'uploading', 'uploading', 'uploading', 'verifying', 'done']);
  });

  it('takes the done message from `message`', async () => {
    const t = new UploadTracker();
    await t.run({ name: 'a.g', total: 1 }, async () => 201, { message: (s) => `HTTP ${s}` });
    expect(t.state).toMatchObject({ phase: 'done', message: 'HTTP 201' });
  });

  it('a failing transfer: failed, and the error goes on to the caller (the command runner logs it)', async () => {
    const t = new UploadTracker();
    const err = new LinkError('http', 'HTTP 500 from upload');
    await expect(
      t.run({ name: 'a.g', total: 1 }, async () => {
        throw err;
      }),
    ).rejects.toBe(err);
    expect(t.state).toMatchObject({ phase: 'failed', message: 'HTTP 500 from upload' });
  });

  it('cancel rejects at once with LinkError "aborted", even when the transport never answers', async () => {
    const t = new UploadTracker();
    const never = deferred<string>();
    let signal: AbortSignal | null = null;
    const p = t.run({ name: 'big.gcode', total: 1e9 }, (h) => {
      signal = h.signal;
      return never.promise;
    });
    expect(t.state.phase).toBe('uploading');
    t.cancel();
    const e = await p.then(
      () => null,
      (x: unknown) => x,
    );
    expect(e).toBeInstanceOf(LinkError);
    expect((e as LinkError).kind).toBe('aborted');
    expect(signal!.aborted).toBe(true);
    expect(t.state.phase).toBe('cancelled');
    // The transport giving up later changes nothing.
    never.reject(new LinkError('network', 'socket closed'));
    await Promise.resolve();
    expect(t.state.phase).toBe('cancelled');
  });
});
