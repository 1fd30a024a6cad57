import type { StoreApi } from 'zustand/vanilla';
import { createSharedStore } from '../../fleet/kernel';

/**
 * Samples for the live chart: time (s since epoch) and one column per series, kept for
 * `windowS` seconds at most. Columns are plain arrays mutated in place; `version` in the store
 * tells readers there is something new (so the store itself stays cheap to update at 10 Hz).
 */
export class History {
  t: number[] = [];
  cols = new Map<string, Array<number | null>>();
  readonly store: StoreApi<{ version: number; names: string[] }> = createSharedStore(() => ({
    version: 0,
    names: [] as string[],
  }));

  constructor(private readonly maxS = 600) {}

  push(atMs: number, values: Record<string, number>): void {
    const t = atMs / 1000;
    const len = this.t.length;
    let namesChanged = false;
    for (const k of Object.keys(values)) {
      if (!this.cols.has(k)) {
        this.cols.set(k, new Array<number | null>(len).fill(null));
        namesChanged = true;
      }
    }
    this.t.push(t);
    for (const [k, col] of this.cols) col.push(values[k] ?? null);
    // Drop what is older than the window (in chunks, to keep pushes cheap).
    const cut = t - this.maxS;
    if (this.t.length > 64 && (this.t[32] ?? Infinity) < cut) {
      let i = 0;
      while (i < this.t.length && (this.t[i] as number) < cut) i++;
      this.t.splice(0, i);
      for (const col of this.cols.values()) col.splice(0, i);
    }
    this.store.setState((s) => ({
      version: s.version + 1,
      names: namesChanged ? [...this.cols.keys()] : s.names,
    }));
  }

  clear(): void {
    this.t = [];
    this.cols = new Map();
    this.store.setState((s) => ({ version: s.version + 1, names: [] }));
  }
}
