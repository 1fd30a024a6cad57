import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, expect, vi } from 'vitest';
import { readdirSync, readFileSync, statSync } from 'node:fs';
import path from 'node:path';
import type { z } from 'zod/mini';
import type { LinkTracker } from '../../src/fleet/contract';
import { LinkError } from '../../src/fleet/errors';
import type { MachineLog } from '../../src/fleet/log';
import type { SimControl, SimSocket, SimSocketHandler, Simulator } from '../../src/fleet/sim';
import type { LinkState, MachineKind, MachineSnapshot } from '../../src/fleet/types';

/**
 * Hostile-input fuzzing for the controller families (issue 15): payloads mutated from real
 * fixtures and simulator answers, with a seeded PRNG (a failure names its seed and iteration, and
 * replays). Used by `src/controllers/<kind>/fuzz.test.ts`.
 *
 * What a payload may do: flip bytes, cut the text, swap a value's type, carry huge numbers
 * (1e400 parses as Infinity), nest thousands deep, carry markup and control characters, and carry
 * `__proto__` / `constructor` / `prototype` keys. What the console must do: never throw past the
 * parser or the session (a payload is parsed, or refused as a protocol error), never let such a
 * key reach an object's prototype, and keep the session alive.
 */

// --- PRNG ------------------------------------------------------------------------------------

/** mulberry32: a small, fast, seeded PRNG (0 ≤ n < 1). */
export function prng(seed: number): () => number {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

export class Rand {
  readonly next: () => number;
  constructor(readonly seed: number) {
    this.next = prng(seed);
  }
  int(n: number): number {
    return Math.floor(this.next() * n);
  }
  pick<T>(xs: readonly T[]): T {
    const x = xs[this.int(xs.length)];
    if (x === undefined) throw new Error('pick from an empty list');
    return x;
  }
  chance(p: number): boolean {
    return this.next() < p;
  }
}

// --- fixtures --------------------------------------------------------------------------------

/** The project's copy of ../shared/fixtures (tests/fixtures/<family>). */
export const FIXTURES = path.resolve(import.meta.dirname, '../fixtures');

/** Every file under `tests/fixtures/<dir>` whose name ends with one of `exts`, as text. */
export function fixtureFiles(
  dir: string,
  exts: readonly string[] = ['.json'],
): Array<{ name: string; text: string }> {
  const root = path.join(FIXTURES, dir);
  const out: Array<{ name: string; text: string }> = [];
  const walk = (d: string): void => {
    for (const f of readdirSync(d).sort()) {
      const p = path.join(d, f);
      if (statSync(p).isDirectory()) walk(p);
      else if (exts.some((e) => f.endsWith(e)))
        out.push({ name: path.relative(root, p), text: readFileSync(p, 'utf8') });
    }
  };
  walk(root);
  return out;
}

/** The lines of a JSON-lines fixture that parse. */
export function jsonLines(text: string): string[] {
  return text.split(/\r?\n/).filter((l) => {
    if (!l.trim()) return false;
    try {
      JSON.parse(l);
      return true;
    } catch {
      return false;
    }
  });
}

// --- mutations -------------------------------------------------------------------------------

type Json = null | boolean | number | string | Json[] | { [k: string]: Json };
const isObj = (v: unknown): v is { [k: string]: Json } =>
  typeof v === 'object' && v !== null && !Array.isArray(v);

/** Strings a controller should never be able to turn into markup, code or a broken layout. */
export const MARKUP: readonly string[] = [
  '<script>globalThis.__fuzzed = 1</script>',
  '<img src=x onerror="globalThis.__fuzzed=1">',
  '"><svg onload=alert(1)>',
  "javascript:alert('x')",
  '{{constructor.constructor("return this")()}}',
  '${7*7}',
  '\u0000\u0001\u0007\u001b[31m',
  '\u202e\u2066RTL\u2069',
  '\ud800',
  '💥'.repeat(50),
  'A'.repeat(100_000),
  '__proto__',
  'constructor',
  'toString',
  'hasOwnProperty',
  '',
  ' ',
  'NaN',
  'Infinity',
  '-0',
  '1e400',
  '0x10',
  'null',
  'undefined',
  'true',
];

/** Values of every JSON type (and the extremes a parser meets). */
const SWAPS: readonly Json[] = [
  null,
  true,
  false,
  0,
  -1,
  1.5,
  Number.MAX_SAFE_INTEGER + 2,
  -Number.MAX_VALUE,
  Number.MAX_VALUE,
  5e-324,
  '',
  'x',
  '12',
  'NaN',
  '-Infinity',
  [],
  {},
  [null],
  [[]],
  { '': null },
];

/** Numbers as JSON text (some beyond what JSON.parse keeps finite). */
const HUGE_TEXT: readonly string[] = [
  '1e400',
  '-1e400',
  '1e-400',
  '123456789012345678901234567890123456789012345678901234567890',
  '-0',
  '9007199254740993',
  '1.7976931348623157e308',
  '4294967296',
  '-2147483649',
];

const PROTO_KEYS = ['__proto__', 'constructor', 'prototype'] as const;
/** What a prototype key carries: a marker that shows pollution, and keys that break things. */
const PROTO_VALUE: Json = {
  polluted: 'fuzz',
  toString: 'x',
  valueOf: 1,
  hasOwnProperty: null,
  isAdmin: true,
};

/** Sets an own property, even `__proto__` (what JSON.parse does with such a key). */
function setOwn(o: { [k: string]: Json }, key: string, value: Json): void {
  Object.defineProperty(o, key, { value, enumerable: true, writable: true, configurable: true });
}

interface Slot {
  get(): Json;
  set(v: Json): void;
  parentObject: { [k: string]: Json } | null;
  key: string | null;
}

/** Up to `max` places in a value, each with a getter and setter (the root included). */
function slots(root: { v: Json }, max = 400): Slot[] {
  const out: Slot[] = [{ get: () => root.v, set: (v) => (root.v = v), parentObject: null, key: null }];
  const queue: Json[] = [root.v];
  while (queue.length > 0 && out.length < max) {
    const v = queue.shift();
    if (Array.isArray(v)) {
      v.forEach((x, i) => {
        out.push({ get: () => v[i] ?? null, set: (nv) => (v[i] = nv), parentObject: null, key: null });
        queue.push(x);
      });
    } else if (isObj(v)) {
      for (const k of Object.keys(v)) {
        out.push({ get: () => v[k] ?? null, set: (nv) => setOwn(v, k, nv), parentObject: v, key: k });
        queue.push(v[k] ?? null);
      }
    }
  }
  return out;
}

export interface Seed {
  /** Where it came from (fixture file, simulator endpoint). */
  name: string;
  text: string;
}

export interface Mutant {
  text: string;
  /** The seed and what was done to it, for the report. */
  how: string;
}

const TOKEN = '"__FUZZ_TEXT_TOKEN__"';

/** Deeper than any recursive walk survives (V8's default stack holds about 10 000 frames). */
export const VERY_DEEP = 20_000;

/** A JSON text nested `depth` deep around `leaf` (built as text: beyond JSON.stringify's stack). */
export function deepText(depth: number, kind: 'array' | 'object', leaf = 'null', key = 'a'): string {
  return kind === 'array'
    ? `${'['.repeat(depth)}${leaf}${']'.repeat(depth)}`
    : `${`{${JSON.stringify(key)}:`.repeat(depth)}${leaf}${'}'.repeat(depth)}`;
}

/**
 * Mutates seeds. JSON seeds get structural mutations (a value's type, huge numbers, nesting,
 * markup, prototype keys, deletions) and text mutations on the result; other text gets text
 * mutations only.
 */
export interface MutatorOptions {
  /** Nesting depths of the "nested" mutation (default 50, 500, 3000). */
  depths?: readonly number[];
  /** Share of nestings 20 000 deep, beyond any recursive walker's stack (default 0.1; slow to fail). */
  veryDeep?: number;
}

export class Mutator {
  readonly rand: Rand;
  private readonly depths: readonly number[];
  private readonly veryDeep: number;
  constructor(seed: number, opts: MutatorOptions = {}) {
    this.rand = new Rand(seed);
    this.depths = opts.depths ?? [50, 500, 3000];
    this.veryDeep = opts.veryDeep ?? 0.1;
  }

  mutate(seed: Seed): Mutant {
    const r = this.rand;
    let parsed: { v: Json } | null = null;
    try {
      parsed = { v: JSON.parse(seed.text) as Json };
    } catch {
      parsed = null;
    }
    const steps: string[] = [];
    let text: string;
    if (parsed && r.chance(0.85)) {
      const n = 1 + r.int(3);
      const rawText: string[] = [];
      for (let i = 0; i < n; i++) steps.push(this.structural(parsed, rawText));
      text = JSON.stringify(parsed.v) ?? 'null';
      // Raw number text (1e400 …) cannot be built as a JS value: placed at a token.
      for (const t of rawText) text = text.replace(TOKEN, t);
      if (r.chance(0.15)) steps.push(this.textual(text, (t) => (text = t)));
    } else {
      text = seed.text;
      const n = 1 + r.int(3);
      for (let i = 0; i < n; i++) steps.push(this.textual(text, (t) => (text = t)));
    }
    return { text, how: `${seed.name}: ${steps.join(', ')}` };
  }

  private structural(root: { v: Json }, rawText: string[]): string {
    const r = this.rand;
    const all = slots(root);
    const slot = r.pick(all);
    const op = r.int(10);
    switch (op) {
      case 0:
      case 1: {
        const v = r.pick(SWAPS);
        slot.set(structuredClone(v));
        return `type swap → ${JSON.stringify(v)}`;
      }
      case 2: {
        const t = r.pick(HUGE_TEXT);
        slot.set(TOKEN.slice(1, -1));
        rawText.push(t);
        return `huge number ${t}`;
      }
      case 3: {
        // Built as text: a value this deep is beyond a recursive JSON.stringify.
        const depth = r.chance(this.veryDeep) ? VERY_DEEP : r.pick(this.depths);
        const kind = r.chance(0.5) ? 'array' : 'object';
        const leaf = JSON.stringify(r.pick(SWAPS));
        slot.set(TOKEN.slice(1, -1));
        rawText.push(deepText(depth, kind, leaf));
        return `nested ${depth} deep (${kind})`;
      }
      case 4: {
        const m = r.pick(MARKUP);
        slot.set(m);
        return `markup ${JSON.stringify(m.slice(0, 24))}`;
      }
      case 5:
      case 6: {
        // A prototype key on an object (the slot's value, or the root).
        const targets = all.map((s) => s.get()).filter(isObj);
        const target = targets.length > 0 ? r.pick(targets) : null;
        const key = r.pick(PROTO_KEYS);
        if (!target) {
          const o: { [k: string]: Json } = {};
          setOwn(o, key, structuredClone(PROTO_VALUE));
          root.v = o;
        } else setOwn(target, key, structuredClone(PROTO_VALUE));
        return `prototype key ${key}`;
      }
      case 7: {
        if (slot.parentObject && slot.key !== null) {
          delete slot.parentObject[slot.key];
          return `deleted ${slot.key}`;
        }
        slot.set(r.chance(0.5) ? {} : []);
        return 'emptied';
      }
      case 8: {
        // A key renamed to markup (keys are shown in some views).
        const objs = all.map((s) => s.get()).filter(isObj);
        const o = objs.length > 0 ? r.pick(objs) : null;
        if (o) {
          const keys = Object.keys(o);
          const k = keys.length > 0 ? r.pick(keys) : 'k';
          const v = o[k] ?? null;
          delete o[k];
          setOwn(o, r.pick(MARKUP).slice(0, 200), v);
        }
        return 'key renamed to markup';
      }
      default: {
        const v = slot.get();
        if (Array.isArray(v) && v.length > 0) {
          const item = v[0] ?? null;
          slot.set(Array.from({ length: 500 }, () => structuredClone(item)));
          return 'array blown up to 500 items';
        }
        slot.set(r.pick(MARKUP));
        return 'replaced by a string';
      }
    }
  }

  private textual(text: string, set: (t: string) => void): string {
    const r = this.rand;
    const op = r.int(5);
    if (text.length === 0) {
      set(r.pick(MARKUP));
      return 'empty → markup';
    }
    switch (op) {
      case 0: {
        const at = r.int(text.length);
        set(text.slice(0, at));
        return `truncated at ${at}`;
      }
      case 1: {
        const chars = text.split('');
        const flips = 1 + r.int(5);
        for (let i = 0; i < flips; i++) {
          const at = r.int(chars.length);
          chars[at] = String.fromCharCode(
            r.pick([0, 0x22, 0x2c, 0x3a, 0x5b, 0x5d, 0x7b, 0x7d, 0x5c, 0xd800, 0xfffd, r.int(256)]),
          );
        }
        set(chars.join(''));
        return `${flips} bytes flipped`;
      }
      case 2: {
        const at = r.int(text.length);
        set(text.slice(0, at) + r.pick(MARKUP) + text.slice(at));
        return 'markup inserted';
      }
      case 3:
        set(text + text.slice(0, r.int(text.length)));
        return 'trailing garbage';
      default: {
        const at = r.int(text.length);
        set(text.slice(0, at) + text.slice(at + 1 + r.int(20)));
        return 'bytes deleted';
      }
    }
  }
}

// --- what must hold --------------------------------------------------------------------------

/** Own keys of the built-in prototypes now (compared before and after a fuzz run). */
export function prototypeKeys(): string {
  const protos: object[] = [
    Object.prototype,
    Array.prototype,
    Function.prototype,
    String.prototype,
    Number.prototype,
  ];
  return protos.map((p) => Reflect.ownKeys(p).map(String).sort().join(',')).join('|');
}

/** A global prototype pollution: the marker our payloads carry shows on a fresh object. */
export function polluted(): string | null {
  const probe: Record<string, unknown> = {};
  for (const k of ['polluted', 'isAdmin']) if (k in probe) return `Object.prototype.${k} is set`;
  if (typeof probe.toString !== 'function') return 'Object.prototype.toString was replaced';
  return null;
}

const BUILTIN_PROTOS = new Set<unknown>([
  Object.prototype,
  Array.prototype,
  null,
  Date.prototype,
  Map.prototype,
  Set.prototype,
  RegExp.prototype,
  Error.prototype,
]);

/**
 * The first object (by path) inside `value` whose prototype is not a built-in one: a
 * `__proto__` key that became a prototype (inherited fields nobody validated). Plain data only:
 * class instances are not walked.
 */
export function foreignPrototype(value: unknown, max = 50_000): string | null {
  const seen = new Set<unknown>();
  const stack: Array<{ v: unknown; p: string }> = [{ v: value, p: '(root)' }];
  let n = 0;
  while (stack.length > 0 && n++ < max) {
    const item = stack.pop();
    if (!item) break;
    const { v, p } = item;
    if (typeof v !== 'object' || v === null || seen.has(v)) continue;
    seen.add(v);
    const proto: unknown = Object.getPrototypeOf(v);
    if (!BUILTIN_PROTOS.has(proto)) {
      // A class instance (a store, a Map subclass) is not data: not walked, not judged.
      const ctor = (proto as { constructor?: unknown } | null)?.constructor;
      if (typeof ctor === 'function' && ctor !== Object && Object.hasOwn(proto as object, 'constructor'))
        continue;
      return p;
    }
    if (Array.isArray(v)) v.forEach((x, i) => stack.push({ v: x, p: `${p}[${i}]` }));
    else if (proto === Object.prototype || proto === null)
      for (const k of Object.keys(v)) stack.push({ v: (v as Record<string, unknown>)[k], p: `${p}.${k}` });
  }
  return null;
}

/** Exception-like words in a message: an exception that was caught and shown as something else. */
export const EXCEPTION_WORDS =
  /TypeError|RangeError|ReferenceError|SyntaxError: (?!Unexpected token|Unexpected end|Expected|Bad control|Bad escaped|Unterminated|Unexpected non-whitespace|Bad Unicode|No number)|is not a function|Cannot read propert|Cannot convert|Maximum call stack|is not iterable|undefined is not|null is not|Invalid array length|Invalid time value|Cannot set propert|Cannot create propert/;

/** Collects what went past the boundary, once per distinct problem (with the payload that did it). */
export class Findings {
  private readonly seen = new Map<string, string>();

  add(kind: string, detail: string, payload: Mutant | string): void {
    const key = `${kind}: ${detail.slice(0, 160)}`;
    if (this.seen.has(key)) return;
    const p = typeof payload === 'string' ? payload : `${payload.how} — ${payload.text.slice(0, 160)}`;
    this.seen.set(key, p);
  }

  get count(): number {
    return this.seen.size;
  }

  /** One line per finding: what, and the payload that showed it. */
  list(): string[] {
    return [...this.seen].map(([k, p]) => `${k}\n      payload: ${p}`);
  }
}

/**
 * Runs a zod schema on a mutated payload (JSON-parsed as the clients do) and checks the boundary:
 * no exception, no foreign prototype in the output. Returns the parse result.
 */
export function parseChecked<S extends z.ZodMiniType>(
  name: string,
  schema: S,
  m: Mutant,
  findings: Findings,
): z.core.util.SafeParseResult<z.output<S>> | null {
  let input: unknown;
  try {
    input = JSON.parse(m.text);
  } catch {
    input = m.text;
  }
  try {
    const r = schema.safeParse(input);
    if (r.success) {
      const f = foreignPrototype(r.data);
      if (f) findings.add('prototype', `${name}: a __proto__ key became the prototype of ${f}`, m);
    }
    return r;
  } catch (e) {
    findings.add('exception', `${name}: ${describe(e)}`, m);
    return null;
  }
}

/** Calls `fn`; an exception is a finding (with `what` and the payload). */
export function guarded<T>(what: string, m: Mutant, findings: Findings, fn: () => T): T | undefined {
  try {
    return fn();
  } catch (e) {
    findings.add('exception', `${what}: ${describe(e)}`, m);
    return undefined;
  }
}

export function describe(e: unknown): string {
  if (e instanceof Error) return `${e.name}: ${e.message.slice(0, 200)}`;
  return String(e).slice(0, 200);
}

// --- sessions --------------------------------------------------------------------------------

/**
 * Watches a session's boundary: every failure handed to its link tracker must be a LinkError (a
 * TypeError there is an exception the poll loop caught and showed as "cannot reach"), and no log
 * line may carry an exception's words.
 */
export function watchBoundary(
  tracker: LinkTracker,
  log: MachineLog,
  findings: Findings,
  current: () => Mutant | string,
): () => void {
  const fail = tracker.fail.bind(tracker);
  tracker.fail = (e, opts) => {
    if (!(e instanceof LinkError))
      findings.add('exception', `caught by the session as a link failure: ${describe(e)}`, current());
    return fail(e, opts);
  };
  let lastSeq = log.store.getState().entries.at(-1)?.seq ?? 0;
  const unsub = log.store.subscribe((s) => {
    for (const entry of s.entries) {
      if (entry.seq <= lastSeq) continue;
      if (EXCEPTION_WORDS.test(entry.text))
        findings.add('exception', `logged by the session: ${entry.text.slice(0, 200)}`, current());
    }
    lastSeq = s.entries.at(-1)?.seq ?? lastSeq;
  });
  return () => {
    tracker.fail = fail;
    unsub();
  };
}

const LINK_STATES: readonly LinkState[] = [
  'connecting',
  'online',
  'reconnecting',
  'needs-login',
  'protocol-error',
  'offline',
];

export function validLink(s: string): s is LinkState {
  return (LINK_STATES as readonly string[]).includes(s);
}

/**
 * A simulator whose next answer on a chosen path is a payload of the test's (consumed once), and
 * whose open sockets the test can write frames into: the session's own ingest path (msw serves it
 * as it serves every session test), with the real simulator answering everything else.
 */
export class FuzzSimulator implements Simulator {
  readonly kind: MachineKind;
  /** Payloads served so far. */
  served = 0;
  private next: { match: (method: string, path: string) => boolean; m: Mutant; status: number } | null = null;
  private readonly open = new Set<SimSocket>();

  constructor(readonly inner: Simulator) {
    this.kind = inner.kind;
  }

  /** The next request `match` accepts gets `m` as its body (status 200 unless said). */
  answerNext(match: (method: string, path: string) => boolean, m: Mutant, status = 200): void {
    this.next = { match, m, status };
  }

  get waiting(): boolean {
    return this.next !== null;
  }

  async fetch(req: Request, p: string): Promise<Response> {
    const n = this.next;
    if (n && n.match(req.method, p)) {
      this.next = null;
      this.served++;
      return new Response(n.m.text, { status: n.status, headers: { 'Content-Type': 'application/json' } });
    }
    return this.inner.fetch(req, p);
  }

  socket(p: string, sock: SimSocket): SimSocketHandler | null {
    const h = this.inner.socket?.(p, sock) ?? null;
    if (!h) return null;
    this.open.add(sock);
    return {
      message: (d) => h.message(d),
      close: () => {
        this.open.delete(sock);
        h.close();
      },
    };
  }

  /** Writes a frame into every open socket; false when none is open. */
  sendFrame(text: string): boolean {
    for (const s of this.open) s.send(text);
    return this.open.size > 0;
  }

  get socketsOpen(): number {
    return this.open.size;
  }

  controls(): SimControl[] {
    return this.inner.controls?.() ?? [];
  }

  dispose(): void {
    this.inner.dispose();
  }
}

/** What a fleet view would show wrongly from this snapshot, or null (the snapshot's contract). */
export function snapshotProblem(s: MachineSnapshot): string | null {
  if (!validLink(s.link)) return `link state "${String(s.link)}"`;
  if (s.link === 'protocol-error' && !s.problem?.message) return 'a protocol error without words';
  const p = s.job?.progress;
  if (p !== null && p !== undefined && !(Number.isFinite(p) && p >= 0 && p <= 1)) return `job progress ${p}`;
  for (const v of [s.job?.elapsed, s.job?.remaining])
    if (v !== null && v !== undefined && !Number.isFinite(v)) return `job time ${v}`;
  for (const [k, v] of Object.entries(s.positions)) if (!Number.isFinite(v)) return `position ${k} = ${v}`;
  for (const t of s.temperatures)
    for (const v of [t.current, t.target])
      if (v !== null && !Number.isFinite(v)) return `temperature ${t.name} = ${v}`;
  const f = foreignPrototype(s);
  if (f) return `a __proto__ key became the prototype of snapshot ${f}`;
  return null;
}

/** Fake timers as the session tests use them (timers and Date; promises and I/O stay real). */
export const FAKE_TIMERS = {
  toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'],
} as const;

/**
 * While a session is fuzzed, an exception thrown in a socket handler or a timer is uncaught: it is
 * recorded as a finding with the payload being fed (instead of an anonymous "Uncaught Exception"
 * of the run). Returns the undo, which puts the previous listeners back.
 */
export function captureUncaught(findings: Findings, current: () => Mutant | string): () => void {
  const onError = (e: unknown) => findings.add('exception', `uncaught: ${describe(e)}`, current());
  const exceptions = process.listeners('uncaughtException');
  const rejections = process.listeners('unhandledRejection');
  process.removeAllListeners('uncaughtException');
  process.removeAllListeners('unhandledRejection');
  process.on('uncaughtException', onError);
  process.on('unhandledRejection', onError);
  return () => {
    process.removeAllListeners('uncaughtException');
    process.removeAllListeners('unhandledRejection');
    for (const l of exceptions) process.on('uncaughtException', l);
    for (const l of rejections) process.on('unhandledRejection', l);
  };
}

/**
 * A fuzz test file's harness: an msw server (unhandled requests fail), `setup` once after it
 * listens, and after each test real timers again and no prototype touched (no polluted key, the
 * same prototype keys as before the file ran).
 */
export function fuzzHarness(setup?: () => Promise<void> | void): { server: ReturnType<typeof setupServer> } {
  const server = setupServer();
  let before = '';
  beforeAll(async () => {
    before = prototypeKeys();
    server.listen({ onUnhandledRequest: 'error' });
    await setup?.();
  });
  afterAll(() => server.close());
  afterEach(() => {
    vi.useRealTimers();
    server.resetHandlers();
    expect(polluted()).toBeNull();
    expect(prototypeKeys()).toBe(before);
  });
  return { server };
}

/** The first findings, one per line, for an assertion's message. */
export function report(findings: Findings): string {
  return findings.list().slice(0, 8).join('\n  ');
}
