import type { SimOptions, SimSocket, SimSocketHandler } from '../../../fleet/sim';
import { splitPath } from '../../../fleet/sim';
import { cloneJson, diffModel, isObject, type Json, type JsonObject } from '../patch';
import { baseModel } from './data/model';
import { MemFs, seedFiles } from './files';

/**
 * The simulated Duet's object model, DSF sessions and model sockets (machine.ts adds the printer).
 * A session lives 8 s after its last request unless a socket is open; no key only without a
 * password; an unknown or expired key gets 403. `WS /machine`: the full model, then diffs sent
 * only after the client's `OK\n` (changes coalesce), `PING\n` → `PONG\n`; refused: close 1008.
 */

export interface DuetSimOptions extends SimOptions {
  /** DSF password; null/undefined: no password protection. */
  password?: string | null;
  /** Session lifetime without socket or request (ms); the document says at least 8 s. */
  sessionTimeoutMs?: number;
}

interface SockState {
  sock: SimSocket;
  key: string | null;
  sent: JsonObject;
  awaitingOk: boolean;
  pending: Json[];
  userSessionId: number;
}

interface Session {
  lastSeen: number;
  sockets: number;
}

export function o(v: Json | undefined): JsonObject {
  if (!isObject(v)) throw new Error('simulator model: object expected');
  return v;
}
export function arr(v: Json | undefined): Json[] {
  return Array.isArray(v) ? v : [];
}

export abstract class DuetSimLink {
  model: JsonObject;
  readonly fs: MemFs;
  password: string | null;
  /** While frozen the sockets stay open but nothing is sent (no patches, no PONG): a dead link. */
  frozen = false;
  /** Refuse WebSocket upgrades (a proxy without WebSocket support): the console polls instead. */
  refuseSockets = false;
  /** HTTP requests received ("GET /machine/noop"), for tests. */
  readonly requests: string[] = [];
  /** PING frames received, for tests. */
  pings = 0;
  /** Told every `messages` event (the standalone simulator turns them into `rr_reply` text). */
  readonly messageListeners: Array<(type: 0 | 1 | 2, content: string) => void> = [];
  protected readonly now: () => number;
  protected readonly sessionTimeoutMs: number;
  protected readonly sessions = new Map<string, Session>();
  protected readonly sockets = new Set<SockState>();
  protected keySeq = 0;
  private userSessionSeq = 0;

  constructor(opts: DuetSimOptions) {
    this.now = opts.now ?? Date.now;
    this.password = opts.password ?? null;
    this.sessionTimeoutMs = opts.sessionTimeoutMs ?? 8000;
    this.model = baseModel(opts.name);
    this.fs = new MemFs(this.now);
    seedFiles(this.fs);
  }

  // ------------------------------------------------------------------ model access

  protected get state(): JsonObject {
    return o(this.model['state']);
  }
  protected get jobObj(): JsonObject {
    return o(this.model['job']);
  }
  protected heaters(): Array<JsonObject | null> {
    return arr(o(this.model['heat'])['heaters']).map((h) => (isObject(h) ? h : null));
  }
  protected axes(): JsonObject[] {
    return arr(o(this.model['move'])['axes']).filter(isObject);
  }
  get status(): string {
    return String(this.state['status']);
  }
  protected setStatus(s: string): void {
    this.state['status'] = s;
  }

  // ------------------------------------------------------------------ messages and sockets

  /** A `messages` event to every connected client (type 0 info, 1 warning, 2 error). */
  message(type: 0 | 1 | 2, content: string): void {
    const m: JsonObject = { content, time: new Date(this.now()).toISOString(), type };
    for (const s of this.sockets) s.pending.push(m);
    for (const l of this.messageListeners) l(type, content);
    this.flush();
  }

  /** Send each client that is not waiting for `OK` what changed since its last frame. */
  flush(): void {
    if (this.frozen) return;
    for (const s of this.sockets) {
      if (s.awaitingOk) continue;
      const d = diffModel(s.sent, this.model);
      if (!d && s.pending.length === 0) continue;
      const frame: JsonObject = { ...(d ?? {}) };
      if (s.pending.length) frame['messages'] = s.pending;
      s.pending = [];
      s.sent = cloneJson(this.model);
      s.awaitingOk = true;
      s.sock.send(JSON.stringify(frame));
    }
  }

  /** Number of frames a client has not acknowledged: 0 or 1 by construction. */
  get openSockets(): number {
    return this.sockets.size;
  }

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    const { pathname, query } = splitPath(path);
    if (pathname !== '/machine' || this.refuseSockets) return null;
    const key = query.get('sessionKey');
    const session = key ? this.liveSession(key) : null;
    if ((key && !session) || (!key && this.password)) {
      queueMicrotask(() => sock.close(1008, '403 Forbidden: invalid session key'));
      return { message: () => undefined, close: () => undefined };
    }
    if (session) session.sockets++;
    const userSessionId = ++this.userSessionSeq;
    const dsf = o(o(this.model['sbc'])['dsf']);
    dsf['userSessions'] = [
      ...arr(dsf['userSessions']),
      {
        accessLevel: 'readWrite',
        id: userSessionId,
        origin: '::ffff:192.0.2.200',
        originId: -1,
        sessionType: 'http',
      },
    ];
    const st: SockState = {
      sock,
      key,
      sent: cloneJson(this.model),
      awaitingOk: true,
      pending: [],
      userSessionId,
    };
    this.sockets.add(st);
    // First frame: the whole object model.
    sock.send(JSON.stringify({ ...this.model, messages: [] }));
    this.flush();
    return {
      message: (data) => {
        const text = data.trim();
        if (text === 'PING') this.pings++;
        if (this.frozen) return;
        if (text === 'OK') {
          st.awaitingOk = false;
          this.flush();
        } else if (text === 'PING') {
          sock.send('PONG\n');
        }
      },
      close: () => this.dropSocket(st),
    };
  }

  private dropSocket(st: SockState): void {
    if (!this.sockets.delete(st)) return;
    if (st.key) {
      const s = this.sessions.get(st.key);
      if (s) {
        s.sockets = Math.max(0, s.sockets - 1);
        s.lastSeen = this.now();
      }
    }
    const dsf = o(o(this.model['sbc'])['dsf']);
    dsf['userSessions'] = arr(dsf['userSessions']).filter(
      (u) => !(isObject(u) && u['id'] === st.userSessionId),
    );
    this.flush();
  }

  /** Close every socket with a code (1001 going away, 1011 server error: the DSF service died). */
  closeSockets(code: number, reason: string): void {
    for (const s of [...this.sockets]) {
      s.sock.close(code, reason);
      this.dropSocket(s);
    }
  }

  protected liveSession(key: string): Session | null {
    const s = this.sessions.get(key);
    if (!s) return null;
    if (s.sockets === 0 && this.now() - s.lastSeen > this.sessionTimeoutMs) {
      this.sessions.delete(key);
      return null;
    }
    return s;
  }

  /** Forget every session (as if DSF restarted). */
  expireSessions(): void {
    this.sessions.clear();
  }
}
