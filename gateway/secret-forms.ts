import { isUtf8 } from 'node:buffer';
import type { GatewaySecrets } from '../src/fleet/contract';

/** Every byte form a machine's secrets can take in a controller's answer (redact.ts searches them). */

/**
 * Secrets shorter than this (in UTF-16 code units, as before) are not searched for: they would
 * mangle every answer.
 */
export const MIN_SECRET_LENGTH = 4;
/** Shortest base64 fragment kept for a secret that sits inside a longer base64 text. */
export const MIN_ALIGNED_BASE64_LENGTH = 6;

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
 * Every byte form of the secrets (one machine's or several), longest first, no duplicates: raw,
 * hex, the base64 family (and its stable inner part at byte offsets 0–2, ≥ 6 characters: Basic
 * auth), each percent-encoded (`URL_SAFE_SETS`, every byte, `%20`/`+`, either case), then JSON-
 * (`JsonStyle`) and HTML-escaped; UTF-16 LE/BE; none under 4 characters. Frozen: reuse per machine.
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
