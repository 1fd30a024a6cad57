import { isUtf8 } from 'node:buffer';
import { Transform, type TransformCallback, type TransformOptions } from 'node:stream';
import zlib from 'node:zlib';
import type { GatewaySecrets } from '../src/fleet/contract';

/**
 * Secret redaction for everything the gateway hands back from a controller (bodies, headers,
 * WebSocket messages, error messages): a controller that echoes an API key or a password, in
 * whatever common encoding, must not hand it to a viewer.
 *
 * - `secretPatterns(secrets)`: every byte form a secret can take in an answer.
 * - `redactBytes(buf, patterns)`: replaces each occurrence by `[redacted]`, byte for byte; bytes
 *   that hold no secret pass through exactly (binary and non-UTF-8 bodies included).
 * - `createRedactor(patterns)`: the same as a Transform stream, across chunk borders.
 * - `decoderFor(contentEncoding)`: a decoding Transform for gzip/deflate/br answers, so that the
 *   decoded bytes can be checked (and sent without a content-encoding), or 'refuse'.
 * - `redactFrame(data, isBinary, patterns)`: one WebSocket message.
 * - `redactText(text, patterns)`: strings (headers, error messages, audit entries).
 *
 * Matching is a single pass of an Aho–Corasick automaton over the bytes: the earliest match wins,
 * the longest at the same position; the replacement text is never searched again.
 */

export const REDACTED = '[redacted]';
const REDACTED_BYTES = Buffer.from(REDACTED, 'utf8');
const EMPTY = Buffer.alloc(0);

/**
 * Secrets shorter than this (in UTF-16 code units, as before) are not searched for: they would
 * mangle every answer.
 */
export const MIN_SECRET_LENGTH = 4;
/** Shortest base64 fragment kept for a secret that sits inside a longer base64 text. */
export const MIN_ALIGNED_BASE64_LENGTH = 6;
export const DEFAULT_MAX_DECODED_BYTES = 256 * 1024 * 1024;

// ---------------------------------------------------------------- the forms of a secret

const ALNUM = 'ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789';

function printableAsciiExcept(chars: string): string {
  let out = '';
  for (let c = 0x21; c < 0x7f; c++) {
    const ch = String.fromCharCode(c);
    if (!chars.includes(ch)) out += ch;
  }
  return out;
}

/** What common percent-encoders leave as is (every other byte becomes %XX). */
const URL_SAFE_SETS: readonly string[] = [
  ALNUM + "-_.!~*'()", // encodeURIComponent
  ALNUM + '-_.~', // RFC 3986 unreserved: Python quote(safe=''), Go QueryEscape, PHP rawurlencode
  ALNUM + '-_.*', // application/x-www-form-urlencoded: URLSearchParams, Java URLEncoder
  ALNUM + '-_.', // PHP urlencode
  ALNUM + "-_.!~*'();/?:@&=+$,#", // encodeURI
  ALNUM + '-_.~/', // Python quote() default
  printableAsciiExcept('"#<>?`{}%'), // WHATWG path percent-encode set (new URL(...).pathname)
  printableAsciiExcept('"#<>\'%'), // WHATWG special-query percent-encode set
];
const URL_SAFE_BYTES: readonly Set<number>[] = URL_SAFE_SETS.map(
  (s) => new Set([...s].map((ch) => ch.charCodeAt(0))),
);

function percentEncode(bytes: Buffer, safe: Set<number>, plusForSpace: boolean, upper: boolean): string {
  let out = '';
  for (const b of bytes) {
    if (safe.has(b)) out += String.fromCharCode(b);
    else if (b === 0x20 && plusForSpace) out += '+';
    else {
      const hex = b.toString(16).padStart(2, '0');
      out += '%' + (upper ? hex.toUpperCase() : hex);
    }
  }
  return out;
}

const EVERY_BYTE = new Set<number>();

/** Percent-encoded variants; `everyByte` adds the one that encodes letters and digits too. */
function urlForms(s: string, everyByte: boolean): string[] {
  const bytes = Buffer.from(s, 'utf8');
  const out: string[] = [];
  for (const safe of everyByte ? [...URL_SAFE_BYTES, EVERY_BYTE] : URL_SAFE_BYTES)
    for (const plus of [false, true])
      for (const upper of [true, false]) out.push(percentEncode(bytes, safe, plus, upper));
  return out;
}

const JSON_SHORT: Readonly<Record<string, string>> = {
  '"': '\\"',
  '\\': '\\\\',
  '\b': '\\b',
  '\f': '\\f',
  '\n': '\\n',
  '\r': '\\r',
  '\t': '\\t',
};

interface JsonStyle {
  /** `/` as `\/` (PHP json_encode). */
  slash: boolean;
  /** Everything above U+007F as \uXXXX (Python json.dumps). */
  ascii: boolean;
  /** `<`, `>`, `&`, `'`, U+2028, U+2029 as \uXXXX (Go encoding/json). */
  html: boolean;
  /** \uXXXX with upper-case hex. */
  upper: boolean;
}

function jsonEscape(s: string, o: JsonStyle): string {
  const u = (unit: number): string => {
    const hex = unit.toString(16).padStart(4, '0');
    return '\\u' + (o.upper ? hex.toUpperCase() : hex);
  };
  let out = '';
  for (const ch of s) {
    const cp = ch.codePointAt(0) ?? 0;
    const short = JSON_SHORT[ch];
    if (short !== undefined) out += short;
    else if (ch === '/' && o.slash) out += '\\/';
    else if (
      cp < 0x20 ||
      (cp >= 0xd800 && cp <= 0xdfff) ||
      (o.ascii && cp > 0x7f) ||
      (o.html && (ch === '<' || ch === '>' || ch === '&' || ch === "'" || cp === 0x2028 || cp === 0x2029))
    ) {
      for (let i = 0; i < ch.length; i++) out += u(ch.charCodeAt(i));
    } else out += ch;
  }
  return out;
}

function jsonForms(s: string): string[] {
  const out: string[] = [];
  for (const slash of [false, true])
    for (const ascii of [false, true])
      for (const html of [false, true])
        for (const upper of [false, true]) out.push(jsonEscape(s, { slash, ascii, html, upper }));
  return out;
}

const HTML_QUOTE = ['&quot;', '&#34;', '&#x22;', '"'];
const HTML_APOS = ['&#39;', '&#x27;', '&apos;', "'"];

function htmlForms(s: string): string[] {
  if (!/[&<>"']/.test(s)) return [s];
  const base = s.replace(/&/g, '&amp;').replace(/</g, '&lt;').replace(/>/g, '&gt;');
  const out: string[] = [];
  for (const q of HTML_QUOTE) for (const a of HTML_APOS) out.push(base.replace(/"/g, q).replace(/'/g, a));
  return out;
}

/**
 * The stable part of the base64 of `raw` when it starts `offset` (0, 1, 2) bytes into a group of
 * three: the characters that depend only on the secret's bits, not on its neighbours.
 */
function alignedBase64(raw: Buffer, offset: number, encoding: 'base64' | 'base64url'): string {
  const text = Buffer.concat([Buffer.alloc(offset), raw]).toString(encoding);
  const start = Math.ceil((8 * offset) / 6);
  const end = Math.floor((8 * offset + 8 * raw.length) / 6);
  return text.slice(start, end);
}

/** Text forms of one secret: raw, hex, base64 family, then percent-, JSON- and HTML-escaped variants. */
function textFormsOf(secret: string): Set<string> {
  const raw = Buffer.from(secret, 'utf8');
  const hex = raw.toString('hex');
  const b64 = raw.toString('base64');
  const b64url = raw.toString('base64url');
  const base = new Set<string>([secret, hex, hex.toUpperCase(), b64, b64.replace(/=+$/, ''), b64url]);
  base.add(b64url + '='.repeat((4 - (b64url.length % 4)) % 4));
  for (const encoding of ['base64', 'base64url'] as const)
    for (const offset of [0, 1, 2]) {
      const part = alignedBase64(raw, offset, encoding);
      if (part.length >= MIN_ALIGNED_BASE64_LENGTH) base.add(part);
    }
  const level1 = new Set(base);
  for (const f of base) for (const g of urlForms(f, f === secret)) level1.add(g);
  const level2 = new Set(level1);
  for (const f of level1) for (const g of jsonForms(f)) level2.add(g);
  const level3 = new Set(level2);
  for (const f of level2) for (const g of htmlForms(f)) level3.add(g);
  return level3;
}

function secretValues(secrets: GatewaySecrets | readonly GatewaySecrets[]): string[] {
  const list: readonly GatewaySecrets[] = isSecretsList(secrets) ? secrets : [secrets];
  const out: string[] = [];
  for (const s of list)
    for (const v of Object.values(s) as unknown[])
      if (typeof v === 'string' && v.length >= MIN_SECRET_LENGTH) out.push(v);
  return out;
}

function isSecretsList(s: GatewaySecrets | readonly GatewaySecrets[]): s is readonly GatewaySecrets[] {
  return Array.isArray(s);
}

function byLengthThenBytes(a: Buffer, b: Buffer): number {
  return b.length - a.length || Buffer.compare(a, b);
}

/**
 * Every byte form the secrets (of one machine, or of several) can take in a controller's answer,
 * longest first, without duplicates: raw UTF-8; hex (both cases); base64, base64 without padding,
 * base64url (with and without padding) and the stable inner part of the base64 of the secret at
 * byte offsets 0, 1 and 2 of a longer base64 text (e.g. `user:password` in Basic auth), when that
 * part is at least 6 characters; each of those percent-encoded (encodeURIComponent, RFC 3986,
 * form encoding, encodeURI, WHATWG path/query, and every byte of the raw secret; `%20` or `+`;
 * upper- or lower-case hex), then JSON-escaped (as JSON.stringify, `\/`, `\u` for non-ASCII,
 * Go's HTML escapes) and HTML-escaped; and UTF-16 (LE and BE). Secrets shorter than 4 characters
 * are left out.
 *
 * The array is frozen: `redactBytes`, `createRedactor` and `redactFrame` compile it once and
 * remember it, so keep and reuse it (one per machine) rather than building a new one per answer.
 */
export function secretPatterns(secrets: GatewaySecrets | readonly GatewaySecrets[]): readonly Buffer[] {
  const byKey = new Map<string, Buffer>();
  const add = (b: Buffer): void => {
    if (b.length >= MIN_SECRET_LENGTH) byKey.set(b.toString('latin1'), b);
  };
  for (const v of secretValues(secrets)) {
    for (const f of textFormsOf(v)) add(Buffer.from(f, 'utf8'));
    const le = Buffer.from(v, 'utf16le');
    add(le);
    add(Buffer.from(le).swap16());
  }
  return Object.freeze([...byKey.values()].sort(byLengthThenBytes));
}

/** The forms of `secretPatterns` that are valid UTF-8, as strings (for string redaction). */
export function secretTextForms(secrets: GatewaySecrets | readonly GatewaySecrets[]): string[] {
  return secretPatterns(secrets)
    .filter((p) => isUtf8(p))
    .map((p) => p.toString('utf8'));
}

// ---------------------------------------------------------------- the automaton

/** Aho–Corasick automaton over byte classes, as a complete transition table. */
class Matcher {
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

interface Compiled {
  source: readonly Buffer[];
  all: Matcher;
  /** Only the patterns that are valid UTF-8: they match only whole characters of valid UTF-8 text. */
  text: Matcher | null;
}

const compiledCache = new WeakMap<readonly Buffer[], Compiled>();

function compiled(patterns: readonly Buffer[]): Compiled {
  const hit = compiledCache.get(patterns);
  if (hit && hit.source.length === patterns.length && hit.source.every((p, i) => p === patterns[i]))
    return hit;
  const c: Compiled = { source: [...patterns], all: new Matcher(patterns), text: null };
  compiledCache.set(patterns, c);
  return c;
}

function textMatcher(c: Compiled): Matcher {
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
class Scanner {
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

function join(parts: Buffer[]): Buffer {
  return parts.length === 0 ? EMPTY : parts.length === 1 ? parts[0]! : Buffer.concat(parts);
}

// ---------------------------------------------------------------- bytes, strings, streams, frames

/**
 * Replaces every occurrence of a pattern in `buf` by `[redacted]` (earliest first, longest at the
 * same position). Returns `buf` itself when there is none: bytes without a secret are never altered.
 */
export function redactBytes(buf: Buffer, patterns: readonly Buffer[]): Buffer {
  const scanner = new Scanner(compiled(patterns).all);
  const parts = scanner.push(buf, true);
  return scanner.found === 0 ? buf : join(parts);
}

function oneBytePerChar(text: string): boolean {
  let high = false;
  for (let i = 0; i < text.length; i++) {
    const c = text.charCodeAt(i);
    if (c > 0xff) return false;
    if (c > 0x7f) high = true;
  }
  return high;
}

/**
 * String redaction (header values, error messages, audit entries). The string is searched as
 * UTF-8 text and, when it has only characters up to U+00FF (Node gives HTTP header values one
 * character per byte, latin1), also as those bytes. Returns `text` itself when nothing was found.
 */
export function redactText(text: string, patterns: readonly Buffer[]): string {
  const c = compiled(patterns);
  if (c.all.maxLength === 0 || text === '') return text;
  let out = text;
  const utf8 = new Scanner(textMatcher(c));
  const parts = utf8.push(Buffer.from(out, 'utf8'), true);
  if (utf8.found > 0) out = join(parts).toString('utf8');
  if (oneBytePerChar(out)) {
    const bytes = new Scanner(c.all);
    const latin1 = bytes.push(Buffer.from(out, 'latin1'), true);
    if (bytes.found > 0) out = join(latin1).toString('latin1');
  }
  return out;
}

const formsCache = new WeakMap<readonly string[], { source: string[]; patterns: readonly Buffer[] }>();

/** The patterns of a list of string forms (as `secretForms` gives), remembered per list. */
export function patternsOfForms(forms: readonly string[]): readonly Buffer[] {
  const hit = formsCache.get(forms);
  if (hit && hit.source.length === forms.length && hit.source.every((f, i) => f === forms[i]))
    return hit.patterns;
  const patterns = Object.freeze(forms.filter((f) => f !== '').map((f) => Buffer.from(f, 'utf8')));
  formsCache.set(forms, { source: [...forms], patterns });
  return patterns;
}

/** A Transform that redacts a byte stream; see `createRedactor`. */
export class Redactor extends Transform {
  readonly #scanner: Scanner;
  readonly maxPatternLength: number;

  constructor(patterns: readonly Buffer[], options: TransformOptions = {}) {
    super({ ...options, objectMode: false, readableObjectMode: false, writableObjectMode: false });
    const m = compiled(patterns).all;
    this.#scanner = new Scanner(m);
    this.maxPatternLength = m.maxLength;
  }

  /** Input bytes received but not yet given out (at most maxPatternLength - 1). */
  get heldBytes(): number {
    return this.#scanner.held;
  }

  /** How many secrets were replaced so far. */
  get redactions(): number {
    return this.#scanner.found;
  }

  override _transform(chunk: Buffer, _encoding: BufferEncoding, callback: TransformCallback): void {
    const out = join(this.#scanner.push(chunk, false));
    if (out.length > 0) this.push(out);
    callback();
  }

  override _flush(callback: TransformCallback): void {
    const out = join(this.#scanner.push(EMPTY, true));
    if (out.length > 0) this.push(out);
    callback();
  }
}

/**
 * `redactBytes` on a stream: a secret split over any number of chunks is found; at most
 * maxPatternLength - 1 bytes are held back, and given out at the end.
 */
export function createRedactor(patterns: readonly Buffer[], options?: TransformOptions): Redactor {
  return new Redactor(patterns, options);
}

/**
 * One WebSocket message (`ws` RawData: Buffer, ArrayBuffer or fragments). A text message that is
 * valid UTF-8 is searched with the patterns that are valid UTF-8 only, so it stays valid UTF-8.
 */
export function redactFrame(
  data: Buffer | ArrayBuffer | Buffer[],
  isBinary: boolean,
  patterns: readonly Buffer[],
): Buffer {
  const buf = Buffer.isBuffer(data)
    ? data
    : data instanceof ArrayBuffer
      ? Buffer.from(data)
      : Buffer.concat(data);
  const c = compiled(patterns);
  const m = !isBinary && isUtf8(buf) ? textMatcher(c) : c.all;
  const scanner = new Scanner(m);
  const parts = scanner.push(buf, true);
  return scanner.found === 0 ? buf : join(parts);
}

// ---------------------------------------------------------------- encoded answers

export class DecodedTooLargeError extends Error {
  readonly code = 'ERR_SHOPDECK_DECODED_TOO_LARGE';
  constructor(readonly limit: number) {
    super(`the controller's answer decodes to more than ${limit} bytes`);
    this.name = 'DecodedTooLargeError';
  }
}

export interface DecoderOptions {
  /** The stream errors (DecodedTooLargeError) once more decoded bytes than this come out. */
  maxDecodedBytes?: number;
}

type Coding = 'gzip' | 'deflate' | 'br';

/** RFC 1950 header: "deflate" is meant to be zlib-wrapped, but some servers send raw deflate. */
function looksLikeZlib(head: Buffer): boolean {
  const cmf = head[0] ?? 0;
  const flg = head[1] ?? 0;
  return (cmf & 0x0f) === 8 && cmf >> 4 <= 7 && (cmf * 256 + flg) % 31 === 0;
}

class Decoder extends Transform {
  #inner: Transform | null = null;
  #head: Buffer = EMPTY;
  #decoded = 0;

  constructor(
    private readonly coding: Coding,
    private readonly limit: number,
  ) {
    super();
  }

  #open(first: Buffer): Transform {
    const z =
      this.coding === 'br'
        ? zlib.createBrotliDecompress()
        : this.coding === 'gzip'
          ? zlib.createGunzip()
          : looksLikeZlib(first)
            ? zlib.createInflate()
            : zlib.createInflateRaw();
    z.on('data', (d: Buffer) => {
      if (this.destroyed) return;
      this.#decoded += d.length;
      if (this.#decoded > this.limit) {
        z.destroy();
        this.destroy(new DecodedTooLargeError(this.limit));
        return;
      }
      if (!this.push(d)) z.pause();
    });
    z.on('error', (e: Error) => this.destroy(e));
    this.#inner = z;
    return z;
  }

  override _read(size: number): void {
    this.#inner?.resume();
    super._read(size);
  }

  override _transform(chunk: Buffer, _encoding: BufferEncoding, callback: TransformCallback): void {
    if (chunk.length === 0) return callback();
    let z = this.#inner;
    let input = chunk;
    if (!z) {
      if (this.coding === 'deflate' && this.#head.length + chunk.length < 2) {
        this.#head = Buffer.concat([this.#head, chunk]);
        return callback();
      }
      input = this.#head.length > 0 ? Buffer.concat([this.#head, chunk]) : chunk;
      this.#head = EMPTY;
      z = this.#open(input);
    }
    z.write(input, (err) => {
      if (!err && !this.destroyed) callback();
    });
  }

  override _flush(callback: TransformCallback): void {
    let z = this.#inner;
    if (!z) {
      // No body at all (HEAD, 204, 304): nothing to decode, nothing to check.
      if (this.#head.length === 0) return callback();
      z = this.#open(this.#head);
      z.write(this.#head);
    }
    z.once('end', () => callback());
    z.end();
  }

  override _destroy(error: Error | null, callback: (error?: Error | null) => void): void {
    this.#inner?.destroy();
    callback(error);
  }
}

/**
 * The decoder for a Content-Encoding header value: a Transform that gives the decoded bytes (to be
 * redacted and forwarded without content-encoding or content-length), null when the answer is not
 * encoded (absent, empty, `identity`), or 'refuse' for any other coding or several codings (the
 * gateway cannot check such an answer). A corrupt or truncated body, or one that decodes to more than
 * `maxDecodedBytes` (default 256 MB), makes the stream error.
 */
export function decoderFor(
  contentEncoding: string | readonly string[] | undefined | null,
  options: DecoderOptions = {},
): Transform | null | 'refuse' {
  const header = typeof contentEncoding === 'string' ? contentEncoding : (contentEncoding ?? []).join(',');
  const codings = header
    .split(',')
    .map((c) => c.trim().toLowerCase())
    .filter((c) => c !== '' && c !== 'identity');
  if (codings.length === 0) return null;
  if (codings.length > 1) return 'refuse';
  const c = codings[0];
  const coding: Coding | null =
    c === 'gzip' || c === 'x-gzip' ? 'gzip' : c === 'deflate' ? 'deflate' : c === 'br' ? 'br' : null;
  if (!coding) return 'refuse';
  const limit = options.maxDecodedBytes ?? DEFAULT_MAX_DECODED_BYTES;
  if (!(limit >= 0)) throw new RangeError('maxDecodedBytes must be a number of bytes');
  return new Decoder(coding, limit);
}
