import { Transform, type TransformCallback } from 'node:stream';
import zlib from 'node:zlib';

/** gzip, deflate and br answers decoded, so that redact.ts can check the decoded bytes. */

const EMPTY = Buffer.alloc(0);

export const DEFAULT_MAX_DECODED_BYTES = 256 * 1024 * 1024;

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
