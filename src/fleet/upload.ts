import { createStore, type StoreApi } from 'zustand/vanilla';
import { UPLOAD_IDLE, type UploadInfo, type UploadState } from '../ui/upload-state';
import { describeError, LinkError } from './errors';
import type { UploadProgress } from './http';

export type { UploadInfo, UploadPhase, UploadState } from '../ui/upload-state';
export { UPLOAD_IDLE, uploadActive } from '../ui/upload-state';

/**
 * The one upload state machine (every family that uploads: xTool, Duet, Prunt):
 *
 *     idle → uploading(loaded, total) → [verifying] → done(message)
 *                         ↘ failed(message)   ↘ cancelled (cancel(): the AbortSignal fires)
 *
 * A tracker holds one upload at a time (the next may start once this one ended). `cancel()`
 * wins at once in the console, whatever the transport does with the abort; anything the
 * cancelled transfer reports afterwards is ignored. Transport: `uploadWithProgress` in http.ts
 * (pass `handle.signal` and `handle.progress`).
 */

export interface UploadStart {
  name: string;
  /** Bytes to send; 0 when unknown (progress events may tell). */
  total: number;
  target?: string | null;
}

/** The running upload's side of the tracker: report progress and the outcome. */
export interface UploadHandle {
  /** Aborted by `cancel()`: pass it to the transfer. */
  readonly signal: AbortSignal;
  /** Progress of the transfer (`onProgress` of `uploadWithProgress`). */
  progress(p: UploadProgress): void;
  /** The transfer is over; the console now checks that the file arrived. */
  verifying(): void;
  done(message?: string | null): void;
  /** A cancellation (LinkError `aborted`, DOM `AbortError`) ends as `cancelled`, the rest as `failed`. */
  fail(error: unknown): void;
}

export class UploadBusy extends Error {
  constructor(name: string) {
    super(`An upload (${name}) is still running`);
    this.name = 'UploadBusy';
  }
}

function isCancellation(e: unknown): boolean {
  if (e instanceof LinkError) return e.kind === 'aborted';
  return typeof e === 'object' && e !== null && (e as { name?: unknown }).name === 'AbortError';
}

export class UploadTracker {
  readonly store: StoreApi<UploadState> = createStore<UploadState>(() => UPLOAD_IDLE);
  private run_ = 0;
  private ctrl: AbortController | null = null;

  get state(): UploadState {
    return this.store.getState();
  }

  /** Begin an upload: `uploading` at 0 bytes. Throws `UploadBusy` while another one runs. */
  start(info: UploadStart): UploadHandle {
    const s = this.state;
    if (s.phase === 'uploading' || s.phase === 'verifying') throw new UploadBusy(s.name);
    const id = ++this.run_;
    const ctrl = new AbortController();
    this.ctrl = ctrl;
    const base: UploadInfo = {
      name: info.name,
      target: info.target ?? null,
      loaded: 0,
      total: Math.max(0, info.total),
    };
    this.store.setState({ ...base, phase: 'uploading' }, true);
    // Only the current run, and only while it is under way, may move the state.
    const update = (from: ReadonlyArray<UploadState['phase']>, next: (s: UploadInfo) => UploadState) => {
      const cur = this.state;
      if (id !== this.run_ || cur.phase === 'idle' || !from.includes(cur.phase)) return;
      this.store.setState(next(cur), true);
    };
    const end = () => {
      if (id === this.run_) this.ctrl = null;
    };
    return {
      signal: ctrl.signal,
      progress: (p) =>
        update(['uploading'], (c) => ({
          ...c,
          phase: 'uploading',
          loaded: Math.max(0, p.loaded),
          total: p.total > 0 ? p.total : c.total,
        })),
      verifying: () =>
        update(['uploading'], (c) => ({ ...c, phase: 'verifying', loaded: c.total || c.loaded })),
      done: (message = null) => {
        update(['uploading', 'verifying'], (c) => ({
          ...c,
          phase: 'done',
          loaded: c.total || c.loaded,
          message,
        }));
        end();
      },
      fail: (error) => {
        update(['uploading', 'verifying'], (c) =>
          isCancellation(error)
            ? { ...c, phase: 'cancelled' }
            : { ...c, phase: 'failed', message: describeError(error) },
        );
        end();
      },
    };
  }

  /**
   * Cancel the transfer: the signal fires and the state is `cancelled` at once. Verification is
   * not cancelled (the file is already on the controller). True when there was one to cancel.
   */
  cancel(): boolean {
    const s = this.state;
    if (s.phase !== 'uploading') return false;
    const { phase: _phase, ...info } = s;
    this.store.setState({ ...info, phase: 'cancelled' }, true);
    this.ctrl?.abort();
    this.ctrl = null;
    return true;
  }

  /** Forget a finished upload (back to idle). Does nothing while one runs. */
  reset(): void {
    const s = this.state;
    if (s.phase === 'uploading' || s.phase === 'verifying') return;
    this.store.setState(UPLOAD_IDLE, true);
  }

  /**
   * Run `work` as one upload: it gets the handle (signal, progress, verifying) and resolves when
   * the file is there. Resolves with its result (a string result is the `done` message unless
   * `message` says otherwise); rejects at once with LinkError `aborted` on cancel.
   */
  async run<T>(
    info: UploadStart,
    work: (h: Pick<UploadHandle, 'signal' | 'progress' | 'verifying'>) => Promise<T>,
    opts: { message?: (result: T) => string | null } = {},
  ): Promise<T> {
    const h = this.start(info);
    const aborted = new Promise<never>((_, reject) => {
      const fire = () => reject(new LinkError('aborted', 'Upload cancelled'));
      if (h.signal.aborted) fire();
      else h.signal.addEventListener('abort', fire, { once: true });
    });
    aborted.catch(() => undefined);
    try {
      const r = await Promise.race([work(h), aborted]);
      h.done(opts.message ? opts.message(r) : typeof r === 'string' ? r : null);
      return r;
    } catch (e) {
      h.fail(e);
      throw e;
    }
  }
}
