import {
  jsonResponse,
  splitPath,
  textResponse,
  type SimControl,
  type SimOptions,
  type Simulator,
} from '../../../fleet/sim';
import { crc32Hex } from '../crc32';
import { cloneJson, isObject, type Json, type JsonObject } from '../patch';
import { DuetSimulator, type DuetSimOptions } from './simulator';

/**
 * A simulated Duet WITHOUT a single-board computer: RepRapFirmware standalone, answering the
 * `rr_*` HTTP API of `../shared/fixtures/duet/rrf-standalone/OpenAPI.yaml` with the corrections of
 * its NOTES.md. Everything here is simulated (the app says so).
 *
 * The printer itself (heaters, the job over time, message boxes, the SD card) is the DSF
 * simulator's (`DuetSimulator`, reused, not copied); only the HTTP surface and the session rules
 * differ:
 * - `GET /rr_connect?password=&time=&sessionKey=yes` → `{err, sessionTimeout, boardType, apiLevel,
 *   sessionKey}`; `err` 1: bad password, 2: no free session (at most MAX_SESSIONS).
 * - Every other request needs `X-Session-Key` of a live session, else **401**. A session ends
 *   SESSION_TIMEOUT_MS after its last request (`HttpResponder.h`). Keyless (IP-based) sessions of
 *   older firmware are not simulated.
 * - `rr_model?key=&flags=`: `{key, flags, result}`; `f` in the flags: the live parts only (an
 *   approximation: the whole of each live top-level part rather than RRF's field-by-field choice);
 *   `seqs` counts changes of each top-level part and of the G-code reply.
 * - `rr_gcode?gcode=` → `{"buff":n}`; its reply (and every message) is appended to the board's ONE
 *   reply buffer and `seqs.reply` counts them (`HttpResponder::HandleGCodeReply`, only while a
 *   session exists). Every `rr_reply`, from any session, counts one client served; once as many
 *   were served as there are sessions the buffer is cleared (`SendGCodeReply`): with one session
 *   the first `rr_reply` takes the reply, whoever asked. Sessions that time out count as served
 *   (`CheckSessions`).
 * - Files: `rr_upload` (raw body, `crc32` checked: `{"err":1}` on a mismatch), `rr_download`,
 *   `rr_filelist` (paged by FILELIST_PAGE, `next`), `rr_fileinfo`, `rr_thumbnail` (paged),
 *   `rr_delete`, `rr_move`, `rr_mkdir`.
 * - Any path that is not `rr_*` (a DSF path such as `/machine/model`): the web page, HTML, 200, as
 *   RRF's web server serves its `www` folder.
 */

export const MAX_SESSIONS = 8;
export const SESSION_TIMEOUT_MS = 8000;
/** Entries per `rr_filelist` answer (RRF fills an output buffer; small here so paging is used). */
export const FILELIST_PAGE = 8;
/** Base64 characters per `rr_thumbnail` answer. */
export const THUMBNAIL_PAGE = 1024;
export const GCODE_BUFFER = 255;

/** What a standalone board answers to any path that is not `rr_*`: its web page (DWC's). */
export const WEB_PAGE =
  '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>Duet Web Control</title></head>' +
  '<body><noscript>Duet Web Control needs JavaScript.</noscript><div id="app"></div></body></html>';

/** Parts a standalone board does not have (DSF only). */
const NOT_STANDALONE = new Set(['messages', 'plugins', 'sbc']);
/** Parts whose values change often: what `flags=…f…` returns (plus `seqs`). */
const LIVE_PARTS = ['boards', 'fans', 'heat', 'inputs', 'job', 'move', 'sensors', 'state', 'tools'];

interface RrSession {
  lastSeen: number;
}

/** RRF stops appending when its output buffers run out; here: this many characters. */
export const REPLY_BUFFER_MAX = 16 * 1024;

export class RrfSimulator implements Simulator {
  readonly kind = 'duet' as const;
  /** The printer (model, card, G-code, time): the DSF simulator's. */
  readonly printer: DuetSimulator;
  password: string | null;
  /** HTTP requests received ("GET /rr_model"), for tests. */
  readonly requests: string[] = [];
  /** What each `rr_reply` was answered, for tests. */
  readonly replyAnswers: string[] = [];
  private readonly now: () => number;
  private readonly sessions = new Map<string, RrSession>();
  private readonly seqs: Record<string, number> = {};
  private readonly lastParts = new Map<string, string>();
  private replySeq = 0;
  /** The one reply buffer of all sessions, and how many clients were served it since it changed. */
  private replyBuffer = '';
  private clientsServed = 0;
  private lastUploadErr = 0;

  constructor(opts: DuetSimOptions) {
    this.now = opts.now ?? Date.now;
    this.password = opts.password ?? null;
    this.printer = new DuetSimulator({ ...opts, password: null });
    this.printer.messageListeners.push((_type, content) => this.reply(content));
  }

  dispose(): void {
    this.printer.dispose();
  }

  /** Live sessions now (expired ones are dropped first). */
  get openSessions(): number {
    this.expire();
    return this.sessions.size;
  }

  /** Forget every session (as if the board restarted its network). */
  expireSessions(): void {
    this.sessions.clear();
  }

  private expire(): void {
    const now = this.now();
    let timedOut = 0;
    for (const [k, s] of this.sessions)
      if (now - s.lastSeen > SESSION_TIMEOUT_MS) {
        this.sessions.delete(k);
        timedOut++;
      }
    if (timedOut === 0) return;
    // CheckSessions: the clients gone are assumed not to have fetched the reply yet.
    this.clientsServed += timedOut;
    if (this.sessions.size === 0 || this.clientsServed >= this.sessions.size) {
      this.replyBuffer = '';
      this.clientsServed = 0;
    }
  }

  /** A reply for every session's `rr_reply`; a code's reply counts even when empty (`always`). */
  private reply(text: string, always = false): void {
    if (!text && !always) return;
    // HandleGCodeReply: nothing is kept (nor counted) while no session exists.
    if (this.sessions.size === 0) return;
    if (this.replyBuffer.length + text.length <= REPLY_BUFFER_MAX) this.replyBuffer += text;
    this.clientsServed = 0;
    this.replySeq++;
  }

  /** `seqs`: each top-level part's change count, the reply count, volume changes. */
  private currentSeqs(): JsonObject {
    for (const [k, v] of Object.entries(this.printer.model)) {
      if (NOT_STANDALONE.has(k)) continue;
      const text = JSON.stringify(v);
      if (this.lastParts.get(k) !== text) {
        this.lastParts.set(k, text);
        this.seqs[k] = (this.seqs[k] ?? 0) + 1;
      }
    }
    return { ...this.seqs, reply: this.replySeq, volChanges: [this.seqs['volumes'] ?? 0, 0] };
  }

  /** The standalone object model: the printer's without the DSF-only parts, with `seqs`. */
  private standaloneModel(): JsonObject {
    const out: JsonObject = {};
    for (const [k, v] of Object.entries(this.printer.model))
      if (!NOT_STANDALONE.has(k)) out[k] = cloneJson(v);
    out['seqs'] = this.currentSeqs();
    return out;
  }

  async fetch(req: Request, path: string): Promise<Response> {
    const { pathname, query } = splitPath(path);
    const method = req.method.toUpperCase();
    this.requests.push(`${method} ${pathname}`);
    if (this.requests.length > 500) this.requests.splice(0, this.requests.length - 500);
    this.expire();
    if (pathname === '/rr_connect' && method === 'GET') {
      if (this.password !== null && query.get('password') !== this.password) return jsonResponse({ err: 1 });
      if (this.sessions.size >= MAX_SESSIONS) return jsonResponse({ err: 2 });
      let key: string;
      do key = String(Math.floor(Math.random() * 0xffffffff) + 1);
      while (this.sessions.has(key));
      this.sessions.set(key, { lastSeen: this.now() });
      const answer: JsonObject = {
        err: 0,
        sessionTimeout: SESSION_TIMEOUT_MS,
        boardType: 'mb6hc',
        apiLevel: 2,
      };
      if (query.get('sessionKey') === 'yes') answer['sessionKey'] = Number(key);
      return jsonResponse(answer);
    }
    // Not the rr_* API (`/machine/model`, `/`, `/anything`): RRF's web server answers with its
    // web page (the card's `0:/www/index.html`, Duet Web Control), 200, never a model.
    if (!pathname.startsWith('/rr_')) return textResponse(WEB_PAGE, 200, 'text/html');
    const key = req.headers.get('X-Session-Key');
    const session = key !== null ? this.sessions.get(key) : undefined;
    if (key === null || !session) return textResponse('{"err":"not authorized"}', 401, 'application/json');
    session.lastSeen = this.now();
    try {
      return await this.route(req, method, pathname, query, key);
    } finally {
      session.lastSeen = this.now();
      this.printer.flush();
    }
  }

  private async route(
    req: Request,
    method: string,
    pathname: string,
    query: URLSearchParams,
    key: string,
  ): Promise<Response> {
    const fs = this.printer.fs;
    const name = query.get('name') ?? '';
    if (method === 'POST' && pathname === '/rr_upload') {
      const data = new Uint8Array(await req.arrayBuffer());
      const crc = query.get('crc32');
      const bad = !name || fs.isDir(name) || (crc !== null && crc.toLowerCase() !== crc32Hex(data));
      this.lastUploadErr = bad ? 1 : 0;
      if (!bad) fs.write(name, data);
      return jsonResponse({ err: this.lastUploadErr });
    }
    if (method !== 'GET') return new Response(null, { status: 404 });
    switch (pathname) {
      case '/rr_disconnect':
        this.sessions.delete(key);
        return jsonResponse({ err: 0 });
      case '/rr_model':
        return jsonResponse(this.modelAnswer(query.get('key') ?? '', query.get('flags') ?? ''));
      case '/rr_gcode': {
        const gcode = query.get('gcode');
        if (gcode === null) return jsonResponse({ err: 1 });
        const reply = this.printer.runCode(gcode);
        this.reply(reply, true);
        return jsonResponse({ buff: GCODE_BUFFER });
      }
      case '/rr_reply': {
        // SendGCodeReply: one client served; cleared once every session was (whoever they are).
        const text = this.replyBuffer;
        if (text !== '') {
          this.clientsServed++;
          if (this.clientsServed >= this.sessions.size) {
            this.replyBuffer = '';
            this.clientsServed = 0;
          }
        }
        this.replyAnswers.push(text);
        if (this.replyAnswers.length > 500) this.replyAnswers.shift();
        return textResponse(text);
      }
      case '/rr_upload':
        return jsonResponse({ err: this.lastUploadErr });
      case '/rr_download': {
        const f = fs.get(name);
        if (!f) return new Response(null, { status: 404 });
        return new Response(f.data.slice().buffer, {
          status: 200,
          headers: { 'Content-Type': 'application/octet-stream' },
        });
      }
      case '/rr_delete': {
        const r = fs.remove(name, query.get('recursive') === 'yes');
        return jsonResponse({ err: r === 'ok' ? 0 : 1 });
      }
      case '/rr_mkdir': {
        const dir = query.get('dir') ?? '';
        if (!dir || fs.exists(dir)) return jsonResponse({ err: 1 });
        fs.mkdirs(dir);
        return jsonResponse({ err: 0 });
      }
      case '/rr_move': {
        const from = query.get('old') ?? '';
        const to = query.get('new') ?? '';
        if (!from || !to || !fs.exists(from)) return jsonResponse({ err: 1 });
        if (fs.exists(to)) {
          if (query.get('deleteexisting') !== 'yes') return jsonResponse({ err: 1 });
          fs.remove(to, true);
        }
        fs.move(from, to);
        return jsonResponse({ err: 0 });
      }
      case '/rr_filelist':
        return jsonResponse(this.fileList(query.get('dir') ?? '', Number(query.get('first') ?? '0')));
      case '/rr_fileinfo': {
        const info = fs.fileInfo(name, false);
        if (!info) return jsonResponse({ err: 1 });
        const thumbs = Array.isArray(info['thumbnails']) ? info['thumbnails'] : [];
        // RRF gives no thumbnail data here (rr_thumbnail pages it), nor DSF's nulls.
        const thumbnails = thumbs.filter(isObject).map((t) => {
          const { data: _data, ...rest } = t;
          return rest;
        });
        return jsonResponse({ err: 0, ...info, thumbnails });
      }
      case '/rr_thumbnail':
        return jsonResponse(this.thumbnail(name, Number(query.get('offset') ?? 'NaN')));
      default:
        return new Response(null, { status: 404 });
    }
  }

  private modelAnswer(key: string, flags: string): JsonObject {
    const model = this.standaloneModel();
    let result: Json = null;
    if (key === '') {
      if (flags.includes('f')) {
        const live: JsonObject = {};
        for (const k of LIVE_PARTS) if (k in model) live[k] = model[k] ?? null;
        live['seqs'] = model['seqs'] ?? null;
        result = live;
      } else result = model;
    } else {
      let cur: Json | undefined = model;
      for (const part of key.split('.')) cur = isObject(cur) ? cur[part] : undefined;
      result = cur ?? null;
    }
    return { key, flags, result };
  }

  private fileList(dir: string, first: number): JsonObject {
    const list = this.printer.fs.list(dir);
    if (!list) return { dir, first, files: [], next: 0, err: 2 };
    const start = Number.isInteger(first) && first > 0 ? first : 0;
    const page = list.slice(start, start + FILELIST_PAGE);
    const next = start + FILELIST_PAGE < list.length ? start + FILELIST_PAGE : 0;
    return { dir, first: start, files: page, next, err: 0 };
  }

  /** Base64 of the thumbnail whose data starts at file offset `offset`, a page at a time. */
  private thumbnail(name: string, offset: number): JsonObject {
    const text = this.printer.fs.text(name);
    if (text === null || !Number.isInteger(offset) || offset < 0 || offset >= text.length)
      return { fileName: name, offset, err: 1 };
    let data = '';
    let at = offset;
    while (at < text.length && data.length < THUMBNAIL_PAGE) {
      const end = text.indexOf('\n', at);
      const line = text.slice(at, end < 0 ? text.length : end).trim();
      if (!line.startsWith(';') || /thumbnail(_\w+)?\s+end/i.test(line)) {
        at = text.length;
        break;
      }
      data += line.replace(/^;\s*/, '');
      at = end < 0 ? text.length : end + 1;
    }
    const more = at < text.length && !/^;\s*thumbnail(_\w+)?\s+end/i.test(text.slice(at).trimStart());
    return { fileName: name, offset, data, next: more ? at : 0, err: 0 };
  }

  controls(): SimControl[] {
    const keep = new Set(['demo', 'heater-fault', 'warning']);
    return [
      ...this.printer.controls().filter((c) => keep.has(c.id) || c.id.startsWith('box-')),
      { id: 'expire-sessions', label: 'Expire all sessions', run: () => this.expireSessions() },
    ];
  }
}

export function createRrfSimulator(opts: SimOptions): Simulator {
  return new RrfSimulator(opts);
}
