import { isUtf8 } from 'node:buffer';

/** redact.ts's matching: an Aho–Corasick automaton (compiled once per pattern list), a chunk scanner. */

export const REDACTED = '[redacted]';
const REDACTED_BYTES = Buffer.from(REDACTED, 'utf8');
export const EMPTY = Buffer.alloc(0);

/** Aho–Corasick automaton over byte classes, as a complete transition table. */
export class Matcher {
  readonly maxLength: number;
  readonly stride: number;
  /** Byte → class (0: a byte that occurs in no pattern). */
  readonly classOf: Uint16Array;
  readonly delta: Uint16Array | Uint32Array;
  /** Length of the longest suffix of the input that is a prefix of a pattern, per state. */
  readonly depth: Uint32Array;
  /** Length of the longest pattern that ends in this state (0: none). */
  readonly outLength: Uint32Array;
  /** 1 when no pattern extends this state. */
  readonly leaf: Uint8Array;

  constructor(patterns: readonly Buffer[]) {
    const list = patterns.filter((p) => p.length > 0);
    this.classOf = new Uint16Array(256);
    let classes = 1;
    let total = 1;
    for (const p of list) {
      total += p.length;
      for (const b of p) if (this.classOf[b] === 0) this.classOf[b] = classes++;
    }
    const stride = classes;
    this.stride = stride;
    this.maxLength = list.reduce((m, p) => Math.max(m, p.length), 0);
    const table = new Uint32Array(total * stride);
    const depth = new Uint32Array(total);
    const terminal = new Uint8Array(total);
    let states = 1;
    for (const p of list) {
      let q = 0;
      for (const b of p) {
        const at = q * stride + (this.classOf[b] ?? 0);
        let next = table[at] ?? 0;
        if (next === 0) {
          next = states++;
          table[at] = next;
          depth[next] = (depth[q] ?? 0) + 1;
        }
        q = next;
      }
      terminal[q] = 1;
    }
    // Breadth first: failure links, then the missing transitions through them.
    const fail = new Uint32Array(states);
    const outLength = new Uint32Array(states);
    const leaf = new Uint8Array(states);
    const queue = new Uint32Array(states);
    let head = 0;
    let tail = 0;
    leaf[0] = 1;
    for (let c = 0; c < stride; c++) {
      const v = table[c] ?? 0;
      if (v !== 0) {
        queue[tail++] = v;
        leaf[0] = 0;
      }
    }
    while (head < tail) {
      const u = queue[head++] ?? 0;
      const f = fail[u] ?? 0;
      outLength[u] = terminal[u] ? (depth[u] ?? 0) : (outLength[f] ?? 0);
      let children = false;
      for (let c = 0; c < stride; c++) {
        const v = table[u * stride + c] ?? 0;
        const viaFail = table[f * stride + c] ?? 0;
        if (v !== 0) {
          children = true;
          fail[v] = viaFail;
          queue[tail++] = v;
        } else table[u * stride + c] = viaFail;
      }
      leaf[u] = children ? 0 : 1;
    }
    const used = table.subarray(0, states * stride);
    this.delta = states <= 0xffff ? Uint16Array.from(used) : used.slice();
    this.depth = depth.slice(0, states);
    this.outLength = outLength;
    this.leaf = leaf;
  }
}

export interface Compiled {
  source: readonly Buffer[];
  all: Matcher;
  /** Only the patterns that are valid UTF-8: they match only whole characters of valid UTF-8 text. */
  text: Matcher | null;
}

const compiledCache = new WeakMap<readonly Buffer[], Compiled>();

export function compiled(patterns: readonly Buffer[]): Compiled {
  const hit = compiledCache.get(patterns);
  if (hit && hit.source.length === patterns.length && hit.source.every((p, i) => p === patterns[i]))
    return hit;
  const c: Compiled = { source: [...patterns], all: new Matcher(patterns), text: null };
  compiledCache.set(patterns, c);
  return c;
}

export function textMatcher(c: Compiled): Matcher {
  if (!c.text) {
    const utf8 = c.source.filter((p) => isUtf8(p));
    c.text = utf8.length === c.source.length ? c.all : new Matcher(utf8);
  }
  return c.text;
}

/**
 * The scanning state across chunks. `pending` holds the bytes not yet given out (at most
 * maxLength - 1 between calls): the longest unfinished partial match, or a found match that a
 * longer one starting at the same place or an earlier one might still replace.
 */
export class Scanner {
  private pending: Buffer = EMPTY;
  /** Bytes of `pending` already fed to the automaton. */
  private scanned = 0;
  private state = 0;
  /** The best match so far (start, end in `pending`), or -1. */
  private matchStart = -1;
  private matchEnd = -1;
  found = 0;

  constructor(private readonly m: Matcher) {}

  get held(): number {
    return this.pending.length;
  }

  /** Feeds `chunk`; returns the parts of the output that are settled (all of it when `final`). */
  push(chunk: Buffer, final: boolean): Buffer[] {
    const buf =
      this.pending.length === 0
        ? chunk
        : chunk.length === 0
          ? this.pending
          : Buffer.concat([this.pending, chunk]);
    const out: Buffer[] = [];
    const m = this.m;
    if (m.maxLength === 0) {
      this.pending = EMPTY;
      if (buf.length > 0) out.push(buf);
      return out;
    }
    const { delta, classOf, stride, depth, outLength, leaf } = m;
    const n = buf.length;
    let i = this.scanned;
    let q = this.state;
    let ms = this.matchStart;
    let me = this.matchEnd;
    let emitted = 0;
    for (;;) {
      while (i < n) {
        q = delta[q * stride + classOf[buf[i]!]!]!;
        i++;
        const len = outLength[q]!;
        if (len !== 0) {
          const s = i - len;
          // Earlier start wins; at the same start, this one ends later: longer.
          if (ms < 0 || s <= ms) {
            ms = s;
            me = i;
          }
        }
        if (ms >= 0) {
          const partial = i - depth[q]!;
          if (partial > ms || (partial === ms && leaf[q] === 1)) {
            // Nothing that starts at or before ms can still grow: settle it, then look again
            // from its end (the bytes after it were seen together with the match).
            if (ms > emitted) out.push(buf.subarray(emitted, ms));
            out.push(REDACTED_BYTES);
            this.found++;
            emitted = me;
            i = me;
            q = 0;
            ms = -1;
            me = -1;
          }
        }
      }
      if (final && ms >= 0) {
        if (ms > emitted) out.push(buf.subarray(emitted, ms));
        out.push(REDACTED_BYTES);
        this.found++;
        emitted = me;
        i = me;
        q = 0;
        ms = -1;
        me = -1;
        continue;
      }
      break;
    }
    if (final) {
      if (emitted < n) out.push(buf.subarray(emitted));
      this.pending = EMPTY;
      this.scanned = 0;
      this.state = 0;
      this.matchStart = -1;
      this.matchEnd = -1;
      return out;
    }
    // Everything before the longest unfinished partial match is settled. (A found match that is
    // still pending starts at or after that point: one that starts before it is settled above.)
    const keep = i - depth[q]!;
    if (keep > emitted) out.push(buf.subarray(emitted, keep));
    // Copy the tail so that a large chunk is not kept alive by a few held bytes.
    this.pending = keep < n ? Buffer.from(buf.subarray(keep)) : EMPTY;
    this.scanned = i - keep;
    this.state = q;
    this.matchStart = ms >= 0 ? ms - keep : -1;
    this.matchEnd = ms >= 0 ? me - keep : -1;
    return out;
  }
}

export function join(parts: Buffer[]): Buffer {
  return parts.length === 0 ? EMPTY : parts.length === 1 ? parts[0]! : Buffer.concat(parts);
}
