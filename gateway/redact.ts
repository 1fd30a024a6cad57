import { isUtf8 } from 'node:buffer';
import { Transform, type TransformCallback, type TransformOptions } from 'node:stream';
import { compiled, EMPTY, join, Scanner, textMatcher } from './redact-scanner';

/**
 * Secret redaction of everything from a controller (bodies, headers, frames, error messages): a
 * secret echoed in any common encoding (secret-forms.ts) becomes `[redacted]`; bytes without one
 * pass exactly. One pass of an Aho–Corasick automaton (redact-scanner.ts): the earliest match
 * wins, the longest at the same position; the replacement is never searched again.
 */

export { REDACTED } from './redact-scanner';
export {
  MIN_ALIGNED_BASE64_LENGTH,
  MIN_SECRET_LENGTH,
  secretPatterns,
  secretTextForms,
} from './secret-forms';
export {
  DecodedTooLargeError,
  decoderFor,
  DEFAULT_MAX_DECODED_BYTES,
  type DecoderOptions,
} from './answer-encoding';

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
