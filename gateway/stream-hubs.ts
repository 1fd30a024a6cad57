import type { SharedStreamDecl } from '../src/fleet/contract';
import type { StreamHub } from './streams';

/**
 * The query that goes upstream with a shared stream and tells its sockets apart: only the
 * parameters the family declares (`query`), each with one of its declared values, in the declared
 * order; whatever else a browser sends is dropped. An Error (400 for the browser): a declared
 * parameter repeated or with a value outside its set.
 */
export function streamQuery(decl: SharedStreamDecl, rawQuery: string): string | Error {
  const given = new URLSearchParams(rawQuery);
  const out = new URLSearchParams();
  for (const [name, values] of Object.entries(decl.query ?? {})) {
    const v = given.getAll(name);
    if (v.length === 0) continue;
    if (v.length > 1) return new Error(`"${name}" given more than once`);
    const value = v[0] ?? '';
    if (!values.includes(value)) return new Error(`"${name}" may only be one of: ${values.join(', ')}`);
    out.set(name, value);
  }
  return out.toString();
}

/** The hubs of a gateway, by machine and stream. */
export class StreamHubs {
  private readonly hubs = new Map<string, StreamHub>();
  /** Browser sockets that joined a shared stream, per machine (tests, benchmarks). */
  private readonly joins = new Map<string, number>();
  /** Hubs being opened: later viewers wait for the same opening. */
  private readonly opening = new Map<string, Promise<StreamHub | { status: number; error: string }>>();

  /** `query`: the declared query only (`streamQuery`), never the browser's own string. */
  static key(machine: string, path: string, query: string): string {
    return `${machine}\u0000${path}\u0000${query}`;
  }

  /**
   * The open hub for `key`, or a new one: `open` connects the controller's socket once, however
   * many viewers ask at the same time.
   */
  async get(
    key: string,
    open: () => Promise<{ hub: StreamHub } | { status: number; error: string }>,
  ): Promise<StreamHub | { status: number; error: string }> {
    const have = this.hubs.get(key);
    if (have?.open) return have;
    const pending = this.opening.get(key);
    if (pending) return pending;
    const p = open().then((r) => {
      this.opening.delete(key);
      if ('status' in r) return r;
      this.hubs.set(key, r.hub);
      return r.hub;
    });
    this.opening.set(key, p);
    return p;
  }

  /** A browser socket of `machine` joined one of its shared streams. */
  noteJoin(machine: string): void {
    this.joins.set(machine, (this.joins.get(machine) ?? 0) + 1);
  }

  /** Shared-stream counts of a machine: browser sockets that joined so far, hubs open now. */
  stats(machine: string): { joined: number; open: number } {
    return { joined: this.joins.get(machine) ?? 0, open: this.ofMachine(machine).length };
  }

  /** Forget a hub that ended (its `onEnd`). */
  forget(key: string, hub: StreamHub): void {
    if (this.hubs.get(key) === hub) this.hubs.delete(key);
  }

  find(key: string): StreamHub | undefined {
    const h = this.hubs.get(key);
    return h?.open ? h : undefined;
  }

  /** Every open hub of a machine (the watch, stats). */
  ofMachine(machine: string): StreamHub[] {
    const out: StreamHub[] = [];
    for (const [k, h] of this.hubs) if (k.startsWith(`${machine}\u0000`) && h.open) out.push(h);
    return out;
  }

  get size(): number {
    let n = 0;
    for (const h of this.hubs.values()) if (h.open) n++;
    return n;
  }

  closeAll(code: number, reason: string): void {
    for (const h of this.hubs.values()) h.close(code, reason);
    this.hubs.clear();
  }
}
