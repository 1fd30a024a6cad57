import type { HeldSend, UpstreamAnswer } from '../../fleet/contract';

/**
 * G-code replies of a standalone Duet, fetched by the gateway alone and handed to each page as
 * its own (Node-safe, pure; one per machine, `gateway.ts` `duetHeldSessionFor`).
 *
 * RepRapFirmware keeps ONE reply buffer for all its HTTP sessions (`HttpResponder.cpp`
 * `SendGCodeReply`): every `rr_reply`, from any session, counts one client served, and the buffer
 * is cleared once as many were served as there are sessions. The gateway holds one session for
 * every page, so whoever asks first takes the reply, whatever code it answers: a viewer's
 * `rr_reply` read (and used up) an operator's reply, and with two pages open the replies went to
 * whichever page polled first. So no browser `rr_reply` ever reaches the board (the gateway
 * answers every one here), and:
 *
 * - `GET rr_gcode?gcode=…` is sent by the gateway (the request was authorized as the code it
 *   carries, as before). The board's answer `{"buff":n}` goes to the page with `replyTicket`, an
 *   unguessable id: the next reply the board gives (the board numbers them in `seqs.reply`) is
 *   that code's, kept for the ticket only. Before the code, replies already waiting are taken as
 *   the board's messages (not for M112: an emergency stop waits for nothing).
 * - `GET rr_reply?after=<n>&ticket=<t>…` (a read: viewer) is answered by the gateway as JSON
 *   `{next, messages, replies}`: the board's own messages numbered by the gateway after `n` (a
 *   page keeps `next` for its next ask; without `after` none, only `next`), and the replies of the
 *   tickets given (each once, then forgotten). A plain `rr_reply` (or `?seq=`) gets the same
 *   answer without messages: nothing of the board's.
 * - The board is asked for a reply only when its `seqs.reply` moved (`rr_model?key=seqs`, read
 *   once for every page asking at once), so each reply is fetched once, by the gateway.
 *
 * Which reply answers which code is RepRapFirmware's order (the HTTP channel runs its codes in
 * turn, as Duet Web Control assumes): a board message that comes while a code waits is taken as
 * that code's reply, and several replies fetched at once (the board appends them) go together.
 */

/** A ticket's code takes the next reply for this long (the page stops waiting then too). */
export const REPLY_WAIT_MS = 30_000;
/** A reply not asked for by its page is kept this long. */
export const REPLY_KEEP_MS = 60_000;
/** The board's messages kept for pages to catch up (the newest; a page asks every second). */
export const MESSAGES_KEPT = 100;
export const MESSAGE_KEEP_MS = 5 * 60_000;
/** Codes waiting for a reply at once (older ones are dropped: their pages stopped waiting). */
export const MAX_WAITING = 64;
/** Tickets one ask may name. */
export const MAX_TICKETS_PER_ASK = 8;
/** Longest reply text kept (RRF's own buffers are smaller; a hostile board is cut). */
export const MAX_REPLY_TEXT = 64 * 1024;

const TICKET = /^[0-9a-f-]{36}$/;
/** An emergency stop in the code: sent at once, never after a read of replies. */
const EMERGENCY = /m0*112(?!\d)/i;

interface Waiting {
  ticket: string;
  at: number;
}

const json = (status: number, body: unknown): UpstreamAnswer => ({
  status,
  headers: { 'content-type': 'application/json' },
  body: JSON.stringify(body),
});

function replySeqOf(a: UpstreamAnswer): number | null {
  if (a.status !== 200) return null;
  try {
    const o: unknown = JSON.parse(a.body);
    if (typeof o !== 'object' || o === null) return null;
    const result = (o as Record<string, unknown>)['result'];
    if (typeof result !== 'object' || result === null) return null;
    const r = (result as Record<string, unknown>)['reply'];
    return typeof r === 'number' && Number.isFinite(r) ? r : null;
  } catch {
    return null;
  }
}

export class RrfReplies {
  /** The board's `seqs.reply` whose reply was fetched (null: none read yet). */
  private seq: number | null = null;
  private readonly waiting: Waiting[] = [];
  private readonly replies = new Map<string, { text: string; at: number }>();
  private readonly messages: Array<{ id: number; text: string; at: number }> = [];
  private head = 0;
  private running: Promise<void> | null = null;
  private again: Promise<void> | null = null;

  constructor(
    private readonly now: () => number = Date.now,
    private readonly newTicket: () => string = () => globalThis.crypto.randomUUID(),
  ) {}

  /** Codes waiting for their reply now (tests). */
  get waitingCount(): number {
    return this.waiting.length;
  }

  /**
   * Reads the board's reply number and, when it moved, the reply (once). Several askers at once
   * share one read, and one more after it (an ask that came during a read sees what came since).
   */
  sync(send: HeldSend): Promise<void> {
    if (!this.running) {
      const run = this.syncNow(send).finally(() => {
        if (this.running === run) this.running = null;
      });
      this.running = run;
      return run;
    }
    this.again ??= this.running
      .catch(() => undefined)
      .then(() => {
        this.again = null;
        return this.sync(send);
      });
    return this.again;
  }

  private async syncNow(send: HeldSend): Promise<void> {
    const seq = replySeqOf(
      await send('GET', '/rr_model', new URLSearchParams({ key: 'seqs', flags: 'd99vno' })),
    );
    if (seq === null || seq === this.seq) return;
    const r = await send('GET', '/rr_reply');
    if (r.status !== 200) return;
    const first = this.seq === null;
    this.seq = seq;
    this.deliver(r.body.slice(0, MAX_REPLY_TEXT), first);
  }

  /** A fetched reply: the oldest waiting code's, else a message for every page. */
  private deliver(text: string, first: boolean): void {
    const now = this.now();
    this.prune(now);
    const w = this.waiting.shift();
    if (w) {
      this.replies.set(w.ticket, { text, at: now });
      return;
    }
    // The first read of a session's life: what waited from before the gateway was there.
    if (first || !text.trim()) return;
    this.messages.push({ id: ++this.head, text, at: now });
    if (this.messages.length > MESSAGES_KEPT) this.messages.shift();
  }

  private prune(now: number): void {
    while (this.waiting.length && now - (this.waiting[0]?.at ?? now) > REPLY_WAIT_MS) this.waiting.shift();
    for (const [t, r] of this.replies) if (now - r.at > REPLY_KEEP_MS) this.replies.delete(t);
    while (this.messages.length && now - (this.messages[0]?.at ?? now) > MESSAGE_KEEP_MS)
      this.messages.shift();
  }

  /**
   * A page's code (`rr_gcode`, already authorized): sent once; the answer carries the ticket of
   * its reply. The board's refusal or anything but `{"buff":n}` goes to the page as it is.
   */
  async code(send: HeldSend, query: URLSearchParams): Promise<UpstreamAnswer> {
    const gcode = query.getAll('gcode').join('\n');
    if (!EMERGENCY.test(gcode)) {
      try {
        await this.sync(send);
      } catch {
        // The code is sent anyway (its own request says whether the board is there).
      }
    }
    const a = await send('GET', '/rr_gcode', query);
    if (a.status !== 200) return a;
    let parsed: unknown;
    try {
      parsed = JSON.parse(a.body);
    } catch {
      return a;
    }
    if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed)) return a;
    const o = parsed as Record<string, unknown>;
    if (typeof o['buff'] !== 'number') return a;
    const now = this.now();
    this.prune(now);
    const ticket = this.newTicket();
    this.waiting.push({ ticket, at: now });
    while (this.waiting.length > MAX_WAITING) this.waiting.shift();
    return json(200, { buff: o['buff'], replyTicket: ticket });
  }

  /** A page's `rr_reply`: the board's messages after `after`, and its own tickets' replies. */
  async ask(send: HeldSend, query: URLSearchParams): Promise<UpstreamAnswer> {
    const tickets = query
      .getAll('ticket')
      .filter((t) => TICKET.test(t))
      .slice(0, MAX_TICKETS_PER_ASK);
    const afterRaw = query.get('after');
    const after = afterRaw !== null && /^\d{1,15}$/.test(afterRaw) ? Number(afterRaw) : null;
    if (after !== null || tickets.length) {
      try {
        await this.sync(send);
      } catch {
        // What is kept is answered; the page's next poll asks again.
      }
    }
    this.prune(this.now());
    const replies: Record<string, string> = {};
    for (const t of tickets) {
      const r = this.replies.get(t);
      if (!r) continue;
      replies[t] = r.text;
      this.replies.delete(t);
    }
    // A number beyond the newest: the gateway restarted since the page asked; all kept is new.
    const from = after === null ? this.head : after > this.head ? 0 : after;
    const messages = this.messages.filter((m) => m.id > from).map((m) => m.text);
    return json(200, { next: this.head, messages, replies });
  }
}
