import { z } from 'zod/mini';
import { LinkError } from '../../fleet/errors';
import { uploadWithProgress, type HttpClient, type RawResponse, type UploadProgress } from '../../fleet/http';
import { crc32Hex } from './crc32';
import { rrfTime } from './gateway';
import { applyPatch, isObject, MAX_DEPTH, nestsDeeper, type Json, type JsonObject } from './patch';
import { connectAnswer, connectRefusal, rrQuery } from './rrf-connect';
import { dirEntrySchema, parsedFileInfoSchema, type DirEntry, type ParsedFileInfo } from './wire';

/**
 * The standalone RepRapFirmware API (`rr_*`, `../shared/fixtures/duet/rrf-standalone/OpenAPI.yaml`
 * and its NOTES.md), for a Duet without a single-board computer. `DuetClient` hands every request
 * here once `connect` learned that the board is standalone, so the session, the commands, the
 * reads and the views stay the DSF ones.
 *
 * - The object model is polled (`poll`): `rr_model?flags=d99fn` (the live parts and `seqs`), then
 *   `rr_model?key=<part>&flags=d99vno` for each part whose `seqs.<part>` moved (all of them the first
 *   time), merged into one raw model shaped as DSF's, which the session validates as a polled DSF
 *   model (`ingest.polled`).
 * - G-code: `rr_gcode?gcode=` answers `{"buff":n}`. Through the gateway (no key in the page) the
 *   answer also carries `replyTicket`, and the page never reads the board's reply buffer: when
 *   `seqs.reply` moves (or a code waits), it asks the gateway's `rr_reply?after=<n>&ticket=<t>`
 *   (`replies.ts`) for the board's messages since n and its own codes' replies. Without a gateway
 *   (msw, tests) the page reads `rr_reply` itself when `seqs.reply` moves: a code waits for the
 *   next reply (as Duet Web Control's PollConnector does), a reply nobody waits for is a message
 *   (`onReply`).
 * - Query values are percent-encoded with `encodeURIComponent` (never `+` for a space: whether RRF
 *   reads `+` as a space is not documented; Duet Web Control never sends one).
 * - Everything is untrusted: each answer is checked with zod, an `rr_model` answer nested deeper
 *   than 64 levels is refused, only part names of letters and digits are taken from `seqs`.
 */

/** Parts `seqs` may name that are not parts of the model. */
const NOT_PARTS = new Set(['reply', 'volChanges']);
/** Fetched once at the first poll: RRF has no `seqs` entry for it. */
const FIRST_ONLY = ['limits'];
const PART_NAME = /^[a-z][A-Za-z0-9]{0,39}$/;
const FORBIDDEN = new Set(['__proto__', 'constructor', 'prototype']);
/** At most this many parts are fetched in one poll (a hostile `seqs` could name thousands). */
const MAX_PARTS = 40;
/** `rr_filelist` pages and `rr_thumbnail` pages followed at most. */
const MAX_PAGES = 200;
/** How long a code waits for its reply (`seqs.reply` moving) before it resolves without one. */
export const REPLY_WAIT_MS = 30_000;

const errAnswer = z.looseObject({ err: z.number() });
const modelAnswer = z.looseObject({ result: z.unknown(), next: z.optional(z.number()) });
const gcodeAnswer = z.looseObject({ buff: z.number(), replyTicket: z.optional(z.string()) });
/** The gateway's `rr_reply` (replies.ts): the board's messages after a number, the tickets' replies. */
const replyFeed = z.looseObject({
  next: z.number(),
  messages: z.array(z.string()),
  replies: z.record(z.string(), z.string()),
});
const fileListAnswer = z.looseObject({
  err: z._default(z.optional(z.number()), 0),
  files: z._default(z.optional(z.array(z.unknown())), []),
  next: z._default(z.optional(z.number()), 0),
});
const thumbnailAnswer = z.looseObject({
  err: z._default(z.optional(z.number()), 0),
  data: z._default(z.optional(z.string()), ''),
  next: z._default(z.optional(z.number()), 0),
});

function failed(what: string, err: number): LinkError {
  return new LinkError('vendor', `${what} failed (the Duet answered err ${err})`, {
    vendorCode: String(err),
  });
}

/** What an upload takes besides its path and body (the DSF client's and this one's). */
export interface UploadOptions {
  timeModified?: Date;
  onProgress?: (p: UploadProgress) => void;
  signal?: AbortSignal;
  commandId?: string;
}

interface ReplyWaiter {
  resolve: (text: string) => void;
  timer: ReturnType<typeof setTimeout>;
  /** The gateway's ticket of the code's reply (none: the next reply read from the board). */
  ticket?: string;
}

export class RrfClient {
  /** The merged raw model (null until the first poll). */
  private model: JsonObject | null = null;
  private seqs: Record<string, number> = {};
  private replySeq: number | null = null;
  /** The gateway's number of the last board message this page got (null: not asked yet). */
  private feedNext: number | null = null;
  private readonly waiters: ReplyWaiter[] = [];
  /**
   * Polls and code sends take turns: a poll in flight while a code is sent could fetch the
   * code's reply before the code waits for it (the reply would then be taken for a message).
   */
  private turn: Promise<unknown> = Promise.resolve();

  private inTurn<T>(fn: () => Promise<T>): Promise<T> {
    const run = this.turn.then(fn, fn);
    this.turn = run.catch(() => undefined);
    return run;
  }
  /** A reply nobody waited for (a message, a macro's echo): the session logs it. */
  onReply: (text: string) => void = () => undefined;

  constructor(
    private readonly http: HttpClient,
    private readonly key: () => string | null,
  ) {}

  /** A new session: the model and the reply counter are read again from scratch. */
  reset(): void {
    this.model = null;
    this.seqs = {};
    this.replySeq = null;
    this.feedNext = null;
    for (const w of this.waiters.splice(0)) {
      clearTimeout(w.timer);
      w.resolve('');
    }
  }

  /** `GET /rr_connect?password=&time=&sessionKey=yes` (only where no gateway answers it: msw). */
  async connect(password: string | undefined, signal?: AbortSignal): Promise<string | null> {
    const q = rrQuery({ password: password ?? '', time: rrfTime(new Date()), sessionKey: 'yes' });
    const a = await this.http.json({ path: `/rr_connect${q}`, signal }, connectAnswer);
    const refused = connectRefusal(a.err ?? 0);
    if (refused) throw refused;
    this.reset();
    return a.sessionKey === undefined || a.sessionKey === null ? null : String(a.sessionKey);
  }

  async disconnect(): Promise<void> {
    await this.http.raw({ path: '/rr_disconnect', timeoutMs: 3000 });
  }

  /** `rr_model?key=&flags=`: the `result`, refused when nested too deep. */
  async modelPart(key: string, flags: string, signal?: AbortSignal): Promise<Json> {
    const a = await this.http.json({ path: `/rr_model${rrQuery({ key, flags })}`, signal }, modelAnswer);
    const result = (a.result ?? null) as Json;
    if (nestsDeeper(result, MAX_DEPTH))
      throw new LinkError('protocol', `rr_model: an answer nested deeper than ${MAX_DEPTH} levels`, {
        path: key || '(root)',
      });
    return result;
  }

  /** Keeps the session (any request does): the cheapest read. */
  async noop(signal?: AbortSignal): Promise<void> {
    await this.modelPart('seqs', 'd99vno', signal);
  }

  /**
   * One poll: the live parts, the parts whose `seqs` moved, the reply when `seqs.reply` moved.
   * Returns the merged raw model (without `seqs`).
   */
  poll(signal?: AbortSignal): Promise<JsonObject> {
    return this.inTurn(() => this.pollNow(signal));
  }

  private async pollNow(signal?: AbortSignal): Promise<JsonObject> {
    const live = await this.modelPart('', 'd99fn', signal);
    if (!isObject(live))
      throw new LinkError('protocol', 'rr_model: the live model is not an object', { path: '(root)' });
    const seqsRaw = live['seqs'];
    const seqs: Record<string, number> = {};
    if (isObject(seqsRaw))
      for (const [k, v] of Object.entries(seqsRaw)) if (typeof v === 'number') seqs[k] = v;
    const first = this.model === null;
    let model: JsonObject = this.model ?? {};
    const { seqs: _seqs, ...liveParts } = live;
    const merged = applyPatch(model, liveParts);
    if (merged.refused !== null)
      throw new LinkError('protocol', `rr_model: ${merged.refused}`, { path: '(root)' });
    model = merged.model;
    const changed = Object.keys(seqs).filter(
      (k) =>
        !NOT_PARTS.has(k) && PART_NAME.test(k) && !FORBIDDEN.has(k) && (first || this.seqs[k] !== seqs[k]),
    );
    if (first) changed.push(...FIRST_ONLY.filter((k) => !changed.includes(k)));
    for (const part of changed.slice(0, MAX_PARTS)) {
      const value = await this.modelPart(part, 'd99vno', signal);
      model = { ...model, [part]: value };
    }
    this.model = model;
    this.seqs = seqs;
    const reply = seqs['reply'];
    const moved = reply !== undefined && this.replySeq !== null && reply !== this.replySeq;
    if (this.key() === null) {
      // Through the gateway: its feed (the board's reply buffer is the gateway's alone).
      if (this.feedNext === null || moved || this.waiters.some((w) => w.ticket !== undefined))
        await this.askGateway(signal);
    } else if (moved) await this.fetchReply(signal);
    if (reply !== undefined) this.replySeq = reply;
    return model;
  }

  /** `rr_reply` read from the board (no gateway: msw, tests): the next waiting code's, or a message. */
  private async fetchReply(signal?: AbortSignal): Promise<void> {
    const r = await this.http.raw({ path: '/rr_reply', signal });
    const i = this.waiters.findIndex((w) => w.ticket === undefined);
    const waiter = i >= 0 ? this.waiters.splice(i, 1)[0] : undefined;
    if (waiter) {
      clearTimeout(waiter.timer);
      waiter.resolve(r.text);
    } else if (r.text.trim()) this.onReply(r.text);
  }

  /**
   * The gateway's `rr_reply?after=<n>&ticket=<t>…` (replies.ts): the board's messages since the
   * last ask (the first ask only learns where they stand) and the replies of this page's codes.
   */
  private async askGateway(signal?: AbortSignal): Promise<void> {
    const q = new URLSearchParams();
    if (this.feedNext !== null) q.set('after', String(this.feedNext));
    for (const w of this.waiters.slice(0, 8)) if (w.ticket !== undefined) q.append('ticket', w.ticket);
    const qs = q.toString().replace(/\+/g, '%20');
    const a = await this.http.json({ path: `/rr_reply${qs ? `?${qs}` : ''}`, signal }, replyFeed);
    const first = this.feedNext === null;
    this.feedNext = a.next;
    if (!first) for (const m of a.messages) if (m.trim()) this.onReply(m);
    for (const [ticket, text] of Object.entries(a.replies)) {
      const i = this.waiters.findIndex((w) => w.ticket === ticket);
      const w = i >= 0 ? this.waiters.splice(i, 1)[0] : undefined;
      if (!w) continue;
      clearTimeout(w.timer);
      w.resolve(text);
    }
  }

  /**
   * `rr_gcode?gcode=`, then its reply (the next `rr_reply`, fetched by `poll`), or "" after
   * REPLY_WAIT_MS. `kick` asks the session for a poll at once.
   */
  async code(code: string, opts: { commandId?: string; async?: boolean }, kick: () => void): Promise<string> {
    // The turn ends once the code is sent and waits (a poll resolves the wait: not awaited here).
    const sent = await this.inTurn(async () => {
      const a = await this.http.json(
        { path: `/rr_gcode${rrQuery({ gcode: code })}`, commandId: opts.commandId, timeoutMs: 10_000 },
        gcodeAnswer,
      );
      if (opts.async) {
        // Not waited for: its reply (taken for it by the gateway) shows as a message.
        if (a.replyTicket !== undefined) {
          const w: ReplyWaiter = {
            ticket: a.replyTicket,
            resolve: (text) => {
              if (text.trim()) this.onReply(text);
            },
            timer: setTimeout(() => {
              const i = this.waiters.indexOf(w);
              if (i >= 0) this.waiters.splice(i, 1);
            }, REPLY_WAIT_MS),
          };
          this.waiters.push(w);
        }
        return { reply: Promise.resolve('') };
      }
      const reply = new Promise<string>((resolve) => {
        const w: ReplyWaiter = {
          ...(a.replyTicket !== undefined ? { ticket: a.replyTicket } : {}),
          resolve,
          timer: setTimeout(() => {
            const i = this.waiters.indexOf(w);
            if (i >= 0) this.waiters.splice(i, 1);
            resolve('');
          }, REPLY_WAIT_MS),
        };
        this.waiters.push(w);
      });
      return { reply };
    });
    kick();
    return sent.reply;
  }

  fileUrl(path: string): string {
    return this.http.url(`/rr_download${rrQuery({ name: path })}`);
  }

  async download(path: string, signal?: AbortSignal): Promise<Blob> {
    return (
      await this.http.blob({ path: `/rr_download${rrQuery({ name: path })}`, timeoutMs: 60_000, signal })
    ).blob;
  }

  async readText(path: string, signal?: AbortSignal): Promise<string> {
    return (
      await this.http.raw({ path: `/rr_download${rrQuery({ name: path })}`, timeoutMs: 30_000, signal })
    ).text;
  }

  /** `POST rr_upload?name=&time=&crc32=` with the raw body; `{"err":1}` is a failed upload. */
  async upload(path: string, body: Blob | ArrayBuffer | string, opts: UploadOptions): Promise<RawResponse> {
    const bytes =
      typeof body === 'string'
        ? new TextEncoder().encode(body)
        : new Uint8Array(body instanceof Blob ? await body.arrayBuffer() : body);
    const headers: Record<string, string> = { 'Content-Type': 'application/octet-stream' };
    const key = this.key();
    if (key) headers['X-Session-Key'] = key;
    if (opts.commandId) headers['X-Shopdeck-Command'] = opts.commandId;
    const q = rrQuery({
      name: path,
      time: opts.timeModified ? rrfTime(opts.timeModified) : undefined,
      crc32: crc32Hex(bytes),
    });
    const r = await uploadWithProgress({
      method: 'POST',
      url: this.http.url(`/rr_upload${q}`),
      body: bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength) as ArrayBuffer,
      headers,
      onProgress: opts.onProgress,
      signal: opts.signal,
      timeoutMs: 600_000,
    });
    let parsed: unknown = null;
    try {
      parsed = JSON.parse(r.text);
    } catch {
      // checked below
    }
    const a = errAnswer.safeParse(parsed);
    if (!a.success) throw new LinkError('protocol', 'rr_upload: an answer without "err"', { path: 'err' });
    if (a.data.err !== 0) throw failed(`Upload of ${path} (CRC or card error)`, a.data.err);
    return r;
  }

  /** `rr_filelist?dir=&first=`, every page (`next` until 0). */
  async listDirectory(dir: string, signal?: AbortSignal): Promise<DirEntry[]> {
    const out: DirEntry[] = [];
    let first = 0;
    for (let page = 0; page < MAX_PAGES; page++) {
      const a = await this.http.json(
        { path: `/rr_filelist${rrQuery({ dir, first })}`, signal },
        fileListAnswer,
      );
      if (a.err === 1) throw failed(`Listing ${dir} (the card is not mounted)`, 1);
      if (a.err !== 0)
        throw new LinkError('http', `Directory ${dir} not found (rr_filelist err ${a.err})`, { status: 404 });
      for (const f of a.files) {
        const e = dirEntrySchema.safeParse(f);
        if (e.success) out.push(e.data);
      }
      if (a.next <= first || a.next === 0) return out;
      first = a.next;
    }
    throw new LinkError('protocol', `rr_filelist: more than ${MAX_PAGES} pages for ${dir}`, { path: 'next' });
  }

  /** `rr_fileinfo?name=`, thumbnails read with `rr_thumbnail` (paged) when asked for. */
  async fileInfo(path: string, thumbnails: boolean, signal?: AbortSignal): Promise<ParsedFileInfo> {
    const raw = await this.http.json({ path: `/rr_fileinfo${rrQuery({ name: path })}`, signal }, errAnswer);
    if (raw.err !== 0)
      throw new LinkError('http', `File ${path} not found (rr_fileinfo err ${raw.err})`, { status: 404 });
    const info = parsedFileInfoSchema.parse(raw);
    if (!thumbnails) return info;
    const thumbs = [];
    for (const t of info.thumbnails) {
      if (t.offset === null) {
        thumbs.push(t);
        continue;
      }
      thumbs.push({ ...t, data: await this.thumbnail(path, t.offset, signal) });
    }
    return { ...info, thumbnails: thumbs };
  }

  private async thumbnail(path: string, offset: number, signal?: AbortSignal): Promise<string | null> {
    let data = '';
    let at = offset;
    for (let page = 0; page < MAX_PAGES; page++) {
      const a = await this.http.json(
        { path: `/rr_thumbnail${rrQuery({ name: path, offset: at })}`, signal },
        thumbnailAnswer,
      );
      if (a.err !== 0) return null;
      data += a.data;
      if (a.next === 0 || a.next <= at) return data;
      at = a.next;
    }
    return null;
  }

  async deleteFile(path: string, opts: { recursive?: boolean; commandId?: string }): Promise<void> {
    const a = await this.http.json(
      {
        path: `/rr_delete${rrQuery({ name: path, recursive: opts.recursive ? 'yes' : undefined })}`,
        commandId: opts.commandId,
      },
      errAnswer,
    );
    if (a.err !== 0) throw failed(`Deleting ${path}`, a.err);
  }

  async move(from: string, to: string, opts: { force?: boolean; commandId?: string }): Promise<void> {
    const a = await this.http.json(
      {
        path: `/rr_move${rrQuery({ old: from, new: to, deleteexisting: opts.force ? 'yes' : undefined })}`,
        commandId: opts.commandId,
      },
      errAnswer,
    );
    if (a.err !== 0) throw failed(`Moving ${from} to ${to} (does the target exist?)`, a.err);
  }

  async makeDirectory(dir: string, commandId?: string): Promise<void> {
    const a = await this.http.json({ path: `/rr_mkdir${rrQuery({ dir })}`, commandId }, errAnswer);
    if (a.err !== 0) throw failed(`Creating folder ${dir}`, a.err);
  }
}
