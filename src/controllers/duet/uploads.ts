import type { StoreApi } from 'zustand/vanilla';
import { describeError, LinkError } from '../../fleet/errors';
import type { UploadProgress } from '../../fleet/http';
import type { RunToken } from '../../fleet/kernel';
import { baseName, type DuetClient } from './client';
import type { DuetState, UploadState } from './state';

/**
 * Uploads (`PUT /machine/file/{path}?timeModified=`) with progress rows in the store. An upload
 * belongs to the run that started it: a stop cancels it, and nothing of it is written after stop.
 */
export interface UploadHost {
  store: StoreApi<DuetState>;
  client: DuetClient;
  now: () => number;
  /** The session's current run (null when it is not started). */
  run: () => RunToken | null;
  /** A command request: sent once, never resent after a 403. */
  send<T>(fn: () => Promise<T>): Promise<T>;
  /** The file changed: its info is stale. */
  filesChanged(paths: readonly string[]): void;
}

export class DuetUploads {
  private seq = 0;
  private readonly aborts = new Map<number, AbortController>();

  constructor(private readonly h: UploadHost) {}

  async upload(file: Blob, path: string, commandId: string): Promise<string> {
    const { store } = this.h;
    // Started during a run: nothing is written once that run ended (stop, or stop and start).
    const run = this.h.run();
    const live = () => run === null || run.alive();
    const id = ++this.seq;
    const ctrl = new AbortController();
    this.aborts.set(id, ctrl);
    const name = baseName(path);
    const set = (p: Partial<UploadState>) => {
      if (!live()) return;
      store.setState((s) => ({ uploads: s.uploads.map((u) => (u.id === id ? { ...u, ...p } : u)) }));
    };
    if (live())
      store.setState((s) => ({
        uploads: [
          ...s.uploads.filter((u) => u.status === 'uploading').slice(-20),
          { id, name, path, loaded: 0, total: file.size, status: 'uploading', error: null },
        ],
      }));
    const lastModified = (file as Blob & { lastModified?: number }).lastModified;
    try {
      // Cancel wins at once in the console, whatever the transport does with the abort.
      const aborted = new Promise<never>((_, reject) =>
        ctrl.signal.addEventListener('abort', () => reject(new LinkError('aborted', 'Upload cancelled'))),
      );
      aborted.catch(() => undefined);
      await Promise.race([
        this.h.send(() =>
          this.h.client.upload(path, file, {
            timeModified: lastModified ? new Date(lastModified) : new Date(this.h.now()),
            onProgress: (p: UploadProgress) => set({ loaded: p.loaded, total: p.total || file.size }),
            signal: ctrl.signal,
            commandId,
          }),
        ),
        aborted,
      ]);
      set({ status: 'done', loaded: file.size });
      this.h.filesChanged([path]);
      return `uploaded ${name}`;
    } catch (e) {
      const cancelled = e instanceof LinkError && e.kind === 'aborted';
      set({ status: cancelled ? 'cancelled' : 'failed', error: describeError(e) });
      throw e;
    } finally {
      this.aborts.delete(id);
    }
  }

  cancel(id: number): void {
    this.aborts.get(id)?.abort();
  }

  /** The session stops: every upload in flight is cancelled (and said so, now, not after stop). */
  stopAll(): void {
    if (this.aborts.size === 0) return;
    const ids = new Set(this.aborts.keys());
    this.h.store.setState((s) => ({
      uploads: s.uploads.map((u) =>
        ids.has(u.id) && u.status === 'uploading'
          ? { ...u, status: 'cancelled', error: 'Cancelled: the session stopped' }
          : u,
      ),
    }));
    for (const a of this.aborts.values()) a.abort();
  }
}
