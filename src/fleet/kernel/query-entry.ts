import { isValidTimeout, type QueryKey } from './query-key';
import type { Deadline, Scheduler } from './scheduler';
import { replaceEqualDeep } from './share';

/** One cached read of the query layer (query.ts): its answer, its read in flight, its observers. */

export type Fetcher<T> = (signal: AbortSignal) => Promise<T>;

/** Why a read's promise rejected when the layer cancelled it (stop, a watcher leaving). */
export class CancelledError extends Error {
  constructor(
    /** Its entry went back to the state before the read. */
    readonly revert: boolean,
    /** Superseded or dropped: a read started again in its place takes over its callers. */
    readonly silent: boolean,
  ) {
    super('CancelledError');
  }
}

/** The cache an entry belongs to. */
export interface EntryOwner {
  /** An unobserved entry is dropped after this long. */
  readonly gcTimeMs: number;
  readonly scheduler: Scheduler;
  remove(entry: Entry<unknown>): void;
}

/** A watcher of an entry (QueryWatch). */
export interface EntryObserver<T> {
  readonly enabled: boolean;
  readonly fn: Fetcher<T>;
  onEntryUpdate(): void;
}

export interface EntryState<T> {
  data: T | undefined;
  /** When `data` was written (ms since epoch), 0 if never. */
  updatedAt: number;
  error: Error | null;
  /** pending: no answer and no error yet. */
  status: 'pending' | 'success' | 'error';
  fetching: boolean;
  /** Stale whatever its age (invalidated, or the last read failed). */
  invalidated: boolean;
}

interface Run<T> {
  readonly promise: Promise<T>;
  /** Rejects the run's promise at once and aborts its signal (no-op once it answered). */
  cancel(err: CancelledError): void;
  /** What a cancel with revert goes back to: the state before the read (and any `set` since). */
  revert: EntryState<T>;
}

/** One key's cached answer, its read in flight, and the watchers showing it. */
export class Entry<T> {
  state: EntryState<T> = {
    data: undefined,
    updatedAt: 0,
    error: null,
    status: 'pending',
    fetching: false,
    invalidated: false,
  };
  /** The latest read function given for this key (by a fetch or a watcher). */
  fn: Fetcher<T> | undefined;
  run: Run<T> | null = null;
  readonly observers: EntryObserver<T>[] = [];
  /** When an unobserved entry is dropped (null: not while observed): one deadline, moved on by reads. */
  private gcAt: number | null = null;
  private readonly gc: Deadline;

  constructor(
    private readonly owner: EntryOwner,
    readonly key: QueryKey,
    readonly hash: string,
  ) {
    this.gc = owner.scheduler.deadline({
      due: () => this.gcAt,
      fire: () => {
        if (this.observers.length === 0 && !this.state.fetching) this.owner.remove(this as Entry<unknown>);
      },
    });
    this.scheduleGc();
  }

  private setState(next: EntryState<T>): void {
    this.state = next;
    for (const o of this.observers.slice()) o.onEntryUpdate();
  }

  isStaleByTime(staleTimeMs: number): boolean {
    const s = this.state;
    if (s.data === undefined || s.invalidated) return true;
    return Date.now() >= s.updatedAt + staleTimeMs;
  }

  isActive(): boolean {
    return this.observers.some((o) => o.enabled);
  }

  invalidate(): void {
    if (!this.state.invalidated) this.setState({ ...this.state, invalidated: true });
  }

  /** Writes an answer (shared with the previous one); `manual`: not a read's, a read in flight goes on. */
  write(data: T, manual: boolean): T {
    const shared = replaceEqualDeep(this.state.data, data);
    const next: EntryState<T> = {
      ...this.state,
      data: shared,
      updatedAt: Date.now(),
      error: null,
      status: 'success',
      invalidated: false,
      fetching: manual ? this.state.fetching : false,
    };
    if (manual && this.run) this.run.revert = next;
    this.setState(next);
    return shared;
  }

  /**
   * Reads the key, or joins the read in flight. `cancelRefetch`: a read in flight of a key that
   * has an answer is cancelled and started again (its callers get the new read's answer).
   */
  fetch(fn: Fetcher<T> | undefined, cancelRefetch = false): Promise<T> {
    if (this.run) {
      if (this.state.data !== undefined && cancelRefetch) this.run.cancel(new CancelledError(false, true));
      else return this.run.promise;
    }
    if (fn) this.fn = fn;
    const read = this.fn ?? this.observers.find((o) => o.fn)?.fn;
    const controller = new AbortController();
    const revert = this.state;
    this.setState({
      ...this.state,
      fetching: true,
      ...(this.state.data === undefined && { error: null, status: 'pending' as const }),
    });

    let settled = false;
    let settle!: { resolve: (v: T) => void; reject: (e: unknown) => void };
    const answer = new Promise<T>((resolve, reject) => (settle = { resolve, reject }));
    // The caller's promise: the answer written (or the error shown), unless the read was cancelled.
    const outcome = async (): Promise<T> => {
      try {
        const data = await answer;
        if (data === undefined) throw new Error(`${this.hash} data is undefined`);
        this.write(data, false);
        return data;
      } catch (e) {
        if (e instanceof CancelledError) {
          if (e.silent) {
            // Started again in its place: this read's callers get that one's answer.
            if (this.run && this.run !== run) return this.run.promise;
            throw e;
          }
          if (this.state.data === undefined) throw e;
          return this.state.data;
        }
        this.setState({
          ...this.state,
          error: e as Error,
          status: 'error',
          fetching: false,
          invalidated: true,
        });
        throw e;
      } finally {
        if (this.run === run) this.run = null;
        this.scheduleGc();
      }
    };
    const run: Run<T> = {
      revert,
      cancel: (err) => {
        if (settled) return;
        settled = true;
        settle.reject(err);
        if (this.run === run) this.run = null;
        if (err.revert) this.setState({ ...run.revert, fetching: false });
        controller.abort();
      },
      promise: outcome(),
    };
    this.run = run;

    let pending: Promise<T>;
    try {
      pending = read ? read(controller.signal) : Promise.reject(new Error(`Missing queryFn: '${this.hash}'`));
    } catch (e) {
      pending = Promise.reject(e);
    }
    Promise.resolve(pending).then(
      (v) => {
        if (settled) return;
        settled = true;
        settle.resolve(v);
      },
      (e: unknown) => {
        if (settled) return;
        settled = true;
        settle.reject(e);
      },
    );
    return run.promise;
  }

  addObserver(o: EntryObserver<T>): void {
    if (this.observers.includes(o)) return;
    this.observers.push(o);
    this.clearGc();
  }

  removeObserver(o: EntryObserver<T>): void {
    const i = this.observers.indexOf(o);
    if (i === -1) return;
    this.observers.splice(i, 1);
    if (this.observers.length === 0) {
      // Nobody shows it any more: the read in flight is cancelled (its request aborted).
      this.run?.cancel(new CancelledError(true, false));
      this.scheduleGc();
    }
  }

  /** Dropped from the cache: its timer cleared, a read in flight cancelled. */
  destroy(): void {
    this.clearGc();
    this.run?.cancel(new CancelledError(false, true));
  }

  private scheduleGc(): void {
    const ms = this.owner.gcTimeMs;
    if (!isValidTimeout(ms)) {
      this.clearGc();
      return;
    }
    this.gcAt = this.owner.scheduler.now() + ms;
    this.gc.update();
  }

  private clearGc(): void {
    this.gcAt = null;
    this.gc.cancel();
  }
}
