import { isUtf8 } from 'node:buffer';
import { Readable, Writable, type Transform } from 'node:stream';
import { pipeline } from 'node:stream/promises';
import zlib from 'node:zlib';
import { describe, expect, it } from 'vitest';
import { redact, secretForms } from './machines';
import {
  createRedactor,
  DecodedTooLargeError,
  decoderFor,
  REDACTED,
  redactBytes,
  redactFrame,
  redactText,
  secretPatterns,
} from './redact';

const KEY = 'tc_live_8f3a9c2b7d1e4f60a5b9';
const PASSWORD = 'Sup3r $ecret/"pässwörd"&<x>';
const R = Buffer.from(REDACTED);

/** Seeded PRNG (mulberry32): the same cases on every run. */
function prng(seed: number): () => number {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

function randomBytes(rand: () => number, n: number, alphabet?: Buffer): Buffer {
  const b = Buffer.alloc(n);
  for (let i = 0; i < n; i++)
    b[i] = alphabet ? (alphabet[Math.floor(rand() * alphabet.length)] ?? 0) : Math.floor(rand() * 256);
  return b;
}

/** Leftmost-longest replacement, the slow obvious way: the reference for the automaton. */
function naiveRedact(buf: Buffer, patterns: readonly Buffer[]): Buffer {
  const out: Buffer[] = [];
  let last = 0;
  let i = 0;
  while (i < buf.length) {
    let best = 0;
    for (const p of patterns) if (p.length > best && buf.subarray(i, i + p.length).equals(p)) best = p.length;
    if (best > 0) {
      out.push(buf.subarray(last, i), R);
      i += best;
      last = i;
    } else i++;
  }
  out.push(buf.subarray(last));
  return Buffer.concat(out);
}

function chunked(rand: () => number, buf: Buffer, maxChunk: number): Buffer[] {
  const chunks: Buffer[] = [];
  for (let i = 0; i < buf.length;) {
    const n = 1 + Math.floor(rand() * maxChunk);
    chunks.push(buf.subarray(i, i + n));
    i += n;
  }
  return chunks;
}

async function collect(chunks: readonly Buffer[], ...streams: Transform[]): Promise<Buffer> {
  const out: Buffer[] = [];
  const sink = new Writable({
    write(chunk: Buffer, _enc, cb) {
      out.push(chunk);
      cb();
    },
  });
  await pipeline([Readable.from(chunks), ...streams, sink]);
  return Buffer.concat(out);
}

function decoder(encoding: string | string[] | undefined, maxDecodedBytes?: number): Transform {
  const d = decoderFor(encoding, maxDecodedBytes === undefined ? {} : { maxDecodedBytes });
  if (d === null || d === 'refuse') throw new Error(`no decoder for ${String(encoding)}`);
  return d;
}

/** The forms a controller could plausibly echo a secret in (built independently of redact.ts). */
function echoes(secret: string): string[] {
  const raw = Buffer.from(secret);
  const b64 = raw.toString('base64');
  return [
    secret,
    encodeURIComponent(secret),
    encodeURIComponent(secret).replace(/%[0-9A-F]{2}/g, (m) => m.toLowerCase()),
    encodeURIComponent(secret).replace(/%20/g, '+'),
    new URLSearchParams({ k: secret }).toString().slice(2),
    JSON.stringify(secret).slice(1, -1),
    JSON.stringify(secret).slice(1, -1).replace(/\//g, '\\/'),
    b64,
    b64.replace(/=+$/, ''),
    raw.toString('base64url'),
    raw.toString('hex'),
    raw.toString('hex').toUpperCase(),
  ];
}

describe('secretPatterns', () => {
  it('holds every encoding of each secret, longest first, without duplicates or short secrets', () => {
    const patterns = secretPatterns({ apiKey: KEY, password: PASSWORD });
    const has = (s: string | Buffer): boolean =>
      patterns.some((p) => p.equals(typeof s === 'string' ? Buffer.from(s) : s));
    for (const secret of [KEY, PASSWORD]) {
      for (const form of echoes(secret)) expect(has(form), form).toBe(true);
      expect(has(Buffer.from(secret, 'utf16le'))).toBe(true);
      expect(has(Buffer.from(secret, 'utf16le').swap16())).toBe(true);
    }
    expect(has(PASSWORD.replace(/&/g, '&amp;').replace(/</g, '&lt;').replace(/>/g, '&gt;'))).toBe(true);
    for (let i = 1; i < patterns.length; i++)
      expect(patterns[i - 1]!.length).toBeGreaterThanOrEqual(patterns[i]!.length);
    expect(new Set(patterns.map((p) => p.toString('hex'))).size).toBe(patterns.length);
    expect(secretPatterns({ apiKey: 'xyz', password: '' })).toEqual([]);
    // Several machines at once (the audit log, gateway-wide messages): the union.
    expect(secretPatterns([{ apiKey: KEY }, { password: PASSWORD }])).toEqual(patterns);
    expect(patterns.every((p) => p.length >= 4)).toBe(true);
  });

  it('finds a secret inside a longer base64 text at any alignment (Basic auth, embedded blobs)', () => {
    const patterns = secretPatterns({ password: 'hunter2-hunter2' });
    for (const encoding of ['base64', 'base64url'] as const) {
      for (let pre = 0; pre < 6; pre++) {
        for (let post = 0; post < 4; post++) {
          const blob = Buffer.from(`${'u'.repeat(pre)}hunter2-hunter2${'!'.repeat(post)}`).toString(encoding);
          const out = redactBytes(Buffer.from(blob), patterns).toString();
          expect(out, `${encoding} ${pre}/${post}`).toContain(REDACTED);
        }
      }
    }
    const basic = Buffer.from('operator:hunter2-hunter2').toString('base64');
    expect(redactBytes(Buffer.from(`Basic ${basic}`), patterns).toString()).toMatch(
      /^Basic [^ ]*\[redacted\]/,
    );
  });

  it('keeps aligned base64 fragments only when they are at least 6 characters', () => {
    // "abcd" at offset 0 leaves only "YWJjZ" (5 characters) that do not depend on the neighbours.
    const forms = secretPatterns({ apiKey: 'abcd' }).map((p) => p.toString());
    expect(forms).toContain('YWJjZA==');
    expect(forms).not.toContain('YWJjZ');
    expect(secretPatterns({ apiKey: 'abcde' }).map((p) => p.toString())).toContain('YWJjZG');
  });
});

describe('redactBytes', () => {
  const patterns = secretPatterns({ apiKey: KEY, password: PASSWORD });

  it('replaces every form of every secret', () => {
    for (const secret of [KEY, PASSWORD]) {
      for (const form of echoes(secret)) {
        const out = redactBytes(Buffer.from(`{"echo":"${form}"}`), patterns).toString();
        expect(out, form).toBe(`{"echo":"${REDACTED}"}`);
      }
    }
    const utf16 = Buffer.concat([Buffer.from('ab'), Buffer.from(KEY, 'utf16le'), Buffer.from('cd')]);
    expect(redactBytes(utf16, patterns).toString()).toBe(`ab${REDACTED}cd`);
  });

  it('passes bytes without a secret through exactly (invalid UTF-8 and binary data)', () => {
    const latin1 = Buffer.from('caf\xe9 \xff\xfe \xc3\x28 ok', 'latin1');
    expect(isUtf8(latin1)).toBe(false);
    const out = redactBytes(latin1, patterns);
    expect(out).toBe(latin1);
    expect(out.toString('hex')).toBe('636166e920fffe20c328206f6b');
    // (What decoding as UTF-8 and encoding again does to it.)
    expect(Buffer.from(latin1.toString('utf8')).equals(latin1)).toBe(false);

    const rand = prng(7);
    const png = Buffer.concat([
      Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0, 0, 0, 13]),
      Buffer.from('IHDR'),
      randomBytes(rand, 200_000),
    ]);
    expect(redactBytes(png, patterns)).toBe(png);
    const withKey = Buffer.concat([png.subarray(0, 1000), Buffer.from(KEY), png.subarray(1000)]);
    const cleaned = redactBytes(withKey, patterns);
    expect(cleaned.equals(Buffer.concat([png.subarray(0, 1000), R, png.subarray(1000)]))).toBe(true);
  });

  it('takes the earliest match, the longest at the same position, and never rescans the replacement', () => {
    const p = (...s: string[]): Buffer[] => s.map((x) => Buffer.from(x));
    const run = (text: string, pats: Buffer[]): string => redactBytes(Buffer.from(text), pats).toString();
    expect(run('xxabcdefyy', p('cd', 'abcdef'))).toBe(`xx${REDACTED}yy`);
    expect(run('abcdefgh', p('cdefgh', 'abcd'))).toBe(`${REDACTED}efgh`);
    expect(run('abcdefg', p('abcd', 'abcdef'))).toBe(`${REDACTED}g`);
    expect(run('abcdabcd', p('abcd', 'bcda'))).toBe(`${REDACTED}${REDACTED}`);
    // "acte" is inside "[redacted]": the output must not be searched again.
    expect(run('acted-key acte', p('acted-key', 'acte'))).toBe(`${REDACTED} ${REDACTED}`);
    expect(run('nothing here', [])).toBe('nothing here');
  });

  it('agrees with a naive leftmost-longest search on random overlapping patterns', () => {
    const rand = prng(42);
    const alphabet = Buffer.from('abc');
    for (let round = 0; round < 400; round++) {
      const pats = Array.from({ length: 1 + Math.floor(rand() * 6) }, () =>
        randomBytes(rand, 1 + Math.floor(rand() * 6), alphabet),
      );
      const text = randomBytes(rand, Math.floor(rand() * 120), alphabet);
      expect(redactBytes(text, pats).toString(), `${pats.join('|')} / ${text}`).toBe(
        naiveRedact(text, pats).toString(),
      );
    }
  });
});

describe('createRedactor', () => {
  const patterns = secretPatterns({ apiKey: KEY, password: PASSWORD });

  function sample(rand: () => number): Buffer {
    const forms = [...echoes(KEY), ...echoes(PASSWORD)];
    const parts: Buffer[] = [];
    for (let k = 0; k < 12; k++) {
      parts.push(randomBytes(rand, Math.floor(rand() * 80)));
      const form = Buffer.from(forms[Math.floor(rand() * forms.length)] ?? KEY);
      // Whole forms, and cut-off starts of them (partial matches that must be given out again).
      parts.push(rand() < 0.7 ? form : form.subarray(0, Math.floor(rand() * form.length)));
    }
    return Buffer.concat(parts);
  }

  it('gives the same output as redactBytes for random chunkings (one byte per chunk included)', async () => {
    const rand = prng(1234);
    for (let round = 0; round < 60; round++) {
      const input = sample(rand);
      const expected = redactBytes(input, patterns);
      expect(expected.equals(input)).toBe(false);
      const maxChunk = round % 3 === 0 ? 1 : 1 + Math.floor(rand() * 64);
      const out = await collect(chunked(rand, input, maxChunk), createRedactor(patterns));
      expect(out.toString('latin1'), `round ${round}`).toBe(expected.toString('latin1'));
    }
  });

  it('agrees with the naive search on random overlapping patterns and chunkings', async () => {
    const rand = prng(99);
    const alphabet = Buffer.from('ab');
    for (let round = 0; round < 150; round++) {
      const pats = Array.from({ length: 1 + Math.floor(rand() * 5) }, () =>
        randomBytes(rand, 1 + Math.floor(rand() * 7), alphabet),
      );
      const input = randomBytes(rand, Math.floor(rand() * 200), alphabet);
      const out = await collect(chunked(rand, input, 1 + Math.floor(rand() * 5)), createRedactor(pats));
      expect(out.toString(), `${pats.join('|')} / ${input}`).toBe(naiveRedact(input, pats).toString());
    }
  });

  it('finds a secret split over one-byte chunks, and holds back at most maxPatternLength - 1 bytes', () => {
    const r = createRedactor(patterns);
    const out: Buffer[] = [];
    r.on('data', (c: Buffer) => out.push(c));
    const rand = prng(5);
    const input = Buffer.concat([
      randomBytes(rand, 5000),
      Buffer.from(`key=${KEY};`),
      randomBytes(rand, 5000),
    ]);
    let maxHeld = 0;
    for (const b of input) {
      r.write(Buffer.from([b]));
      maxHeld = Math.max(maxHeld, r.heldBytes);
      expect(r.heldBytes).toBeLessThanOrEqual(r.maxPatternLength - 1);
    }
    // The key minus its last byte was held back (not given out), and no more.
    expect(maxHeld).toBe(KEY.length - 1);
    r.end();
    const expected = redactBytes(input, patterns);
    return new Promise<void>((resolve) =>
      r.on('end', () => {
        expect(Buffer.concat(out).equals(expected)).toBe(true);
        expect(r.redactions).toBe(1);
        expect(Buffer.concat(out).includes(KEY)).toBe(false);
        resolve();
      }),
    );
  });

  it('gives out bytes that cannot start a secret at once', () => {
    const r = createRedactor(patterns);
    r.write(Buffer.from('x'.repeat(1000)));
    expect(r.heldBytes).toBe(0);
    expect(r.readableLength).toBe(1000);
    r.write(Buffer.from(KEY.slice(0, 10)));
    expect(r.heldBytes).toBe(10);
    expect(r.readableLength).toBe(1000);
    r.write(Buffer.from('zz'));
    expect(r.heldBytes).toBe(0);
    expect(r.readableLength).toBe(1012);
  });

  it('applies backpressure like any Transform', async () => {
    const r = createRedactor(patterns, { highWaterMark: 16 * 1024 });
    const chunk = Buffer.alloc(64 * 1024, 'a');
    let accepted = 0;
    let writes = 0;
    while (r.write(chunk) && writes < 1000) {
      accepted++;
      writes++;
    }
    // Nobody reads: writes are refused long before 1000 chunks, and little is buffered.
    expect(accepted).toBeLessThan(5);
    expect(r.readableLength + r.writableLength).toBeLessThan(5 * chunk.length);
    r.end(Buffer.from(KEY));
    const out: Buffer[] = [];
    for await (const c of r) out.push(c as Buffer);
    const all = Buffer.concat(out);
    expect(all.length).toBe((accepted + 1) * chunk.length + REDACTED.length);
    expect(all.subarray(-REDACTED.length).toString()).toBe(REDACTED);
  });
});

describe('decoderFor', () => {
  const patterns = secretPatterns({ apiKey: KEY });
  const body = Buffer.from(`{"status":"idle","apiKey":"${KEY}","note":"${'n'.repeat(5000)}"}`);
  const expected = redactBytes(body, patterns);

  it('knows which answers it can decode', () => {
    for (const e of [undefined, '', 'identity', ' Identity ', ['identity']]) expect(decoderFor(e)).toBeNull();
    for (const e of [
      'compress',
      'zstd',
      'gzip, br',
      'gzip,gzip',
      ['gzip', 'deflate'],
      'x-custom',
      'gzip;q=1',
    ])
      expect(decoderFor(e), String(e)).toBe('refuse');
    for (const e of ['gzip', 'x-gzip', 'GZIP', 'deflate', 'br', 'identity, gzip', ['gzip']])
      expect(decoderFor(e), String(e)).not.toBeNull();
  });

  const encodings: Array<[string, Buffer]> = [
    ['gzip', zlib.gzipSync(body)],
    ['x-gzip', zlib.gzipSync(body)],
    ['deflate', zlib.deflateSync(body)],
    ['deflate', zlib.deflateRawSync(body)],
    ['br', zlib.brotliCompressSync(body)],
  ];
  for (const [encoding, encoded] of encodings) {
    it(`decodes ${encoding} (${encoded[0]?.toString(16)}…) so the secret is found, whatever the chunks`, async () => {
      expect(encoded.includes(KEY)).toBe(false);
      expect(redactBytes(encoded, patterns).equals(encoded)).toBe(true);
      const rand = prng(encoded.length);
      for (const max of [1, 7, 4096]) {
        const out = await collect(chunked(rand, encoded, max), decoder(encoding), createRedactor(patterns));
        expect(out.equals(expected)).toBe(true);
      }
    });
  }

  it('errors on a corrupt or truncated body', async () => {
    const gz = zlib.gzipSync(body);
    const corrupt = Buffer.from(gz);
    corrupt.fill(0x55, 12, 40);
    await expect(collect([corrupt], decoder('gzip'), createRedactor(patterns))).rejects.toThrow();
    await expect(collect([gz.subarray(0, gz.length - 10)], decoder('gzip'))).rejects.toThrow();
    await expect(collect([Buffer.from('not brotli at all')], decoder('br'))).rejects.toThrow();
    await expect(collect([Buffer.from([0x78])], decoder('deflate'))).rejects.toThrow();
  });

  it('gives an empty body for an empty answer (HEAD, 204)', async () => {
    for (const e of ['gzip', 'deflate', 'br']) expect((await collect([], decoder(e))).length).toBe(0);
  });

  it('stops a decompression bomb at maxDecodedBytes', async () => {
    const bomb = zlib.gzipSync(Buffer.alloc(20 * 1024 * 1024));
    let seen = 0;
    const d = decoder('gzip', 1024 * 1024);
    const count = new Writable({
      write(chunk: Buffer, _enc, cb) {
        seen += chunk.length;
        cb();
      },
    });
    await expect(pipeline(Readable.from([bomb]), d, count)).rejects.toBeInstanceOf(DecodedTooLargeError);
    expect(seen).toBeLessThanOrEqual(1024 * 1024);
    // Exactly at the limit is fine.
    const exact = await collect([zlib.gzipSync(Buffer.alloc(4096))], decoder('gzip', 4096));
    expect(exact.length).toBe(4096);
    const br = zlib.brotliCompressSync(Buffer.alloc(8 * 1024 * 1024));
    await expect(collect([br], decoder('br', 1000))).rejects.toBeInstanceOf(DecodedTooLargeError);
  });

  it('does not decode ahead of a reader that does not read', async () => {
    const d = decoder('gzip');
    const big = zlib.gzipSync(Buffer.alloc(32 * 1024 * 1024, 'z'));
    d.write(big);
    await new Promise((r) => setTimeout(r, 200));
    expect(d.readableLength).toBeLessThan(1024 * 1024);
    d.end();
    let total = 0;
    for await (const c of d) total += (c as Buffer).length;
    expect(total).toBe(32 * 1024 * 1024);
  });
});

describe('redactFrame', () => {
  const patterns = secretPatterns({ apiKey: KEY, password: PASSWORD });

  it('redacts Buffer, ArrayBuffer and fragmented messages', () => {
    const text = Buffer.from(`{"key":"${KEY}"}`);
    expect(redactFrame(text, false, patterns).toString()).toBe(`{"key":"${REDACTED}"}`);
    const ab = new ArrayBuffer(text.length);
    new Uint8Array(ab).set(text);
    expect(redactFrame(ab, false, patterns).toString()).toBe(`{"key":"${REDACTED}"}`);
    const cut = 12;
    expect(redactFrame([text.subarray(0, cut), text.subarray(cut)], false, patterns).toString()).toBe(
      `{"key":"${REDACTED}"}`,
    );
    const bin = Buffer.concat([Buffer.from([0, 1, 2]), Buffer.from(KEY, 'utf16le'), Buffer.from([0xff])]);
    expect(
      redactFrame(bin, true, patterns).equals(
        Buffer.concat([Buffer.from([0, 1, 2]), R, Buffer.from([0xff])]),
      ),
    ).toBe(true);
    const clean = Buffer.from([0xc3, 0x28, 0xff, 0x00]);
    expect(redactFrame(clean, true, patterns)).toBe(clean);
  });

  it('keeps text messages valid UTF-8', () => {
    const msg = Buffer.from(`é ${PASSWORD} ü ${JSON.stringify(PASSWORD)} 😀`);
    const out = redactFrame(msg, false, patterns);
    expect(isUtf8(out)).toBe(true);
    expect(out.toString()).toBe(`é ${REDACTED} ü "${REDACTED}" 😀`);
    // A pattern that is not valid UTF-8 could cut a character in two: not used on text.
    const odd = [Buffer.from([0x80, 0x41, 0x42, 0x43])];
    const text = Buffer.from('\u00c0ABC');
    expect(redactFrame(text, false, odd).equals(text)).toBe(true);
    expect(redactFrame(text, true, odd).equals(Buffer.from([0xc3, ...R]))).toBe(true);
  });
});

describe('string redaction (machines.ts redact/secretForms)', () => {
  it('secretForms still lists strings, now with the new forms', () => {
    const forms = secretForms({ apiKey: KEY, password: PASSWORD });
    for (const form of [...echoes(KEY), ...echoes(PASSWORD)]) expect(forms).toContain(form);
    expect(forms.every((f) => typeof f === 'string' && f.length >= 4)).toBe(true);
    expect(secretForms({ apiKey: 'xy' })).toEqual([]);
  });

  it('redacts error messages and header values, also as Node gives headers (latin1)', () => {
    const forms = secretForms({ apiKey: KEY, password: PASSWORD });
    const hex = Buffer.from(KEY).toString('hex');
    expect(redact(`connect failed for ${hex} and ${Buffer.from(KEY).toString('base64url')}`, forms)).toBe(
      `connect failed for ${REDACTED} and ${REDACTED}`,
    );
    // A header holding the UTF-8 password arrives as one character per byte.
    const header = Buffer.from(`pw=${PASSWORD}`).toString('latin1');
    expect(header).not.toContain(PASSWORD);
    expect(redact(header, forms)).toBe(`pw=${REDACTED}`);
    expect(redact('caf\u00e9 ok', forms)).toBe('caf\u00e9 ok');
    expect(redactText('nothing to see', secretPatterns({ apiKey: KEY }))).toBe('nothing to see');
  });

  it('replaces in one pass (a secret inside "[redacted]" leaves it alone)', () => {
    const forms = secretForms({ apiKey: 'acted-key', password: 'acte' });
    expect(redact('acted-key and acte', forms)).toBe(`${REDACTED} and ${REDACTED}`);
  });
});
