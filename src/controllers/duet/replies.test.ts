import { describe, expect, it } from 'vitest';
import type { HeldSend, UpstreamAnswer } from '../../fleet/contract';
import { RrfReplies } from './replies';

/** A board as the gateway's relay sees it: a reply number and ONE buffer (one session). */
function board() {
  const b = { seq: 10, buffer: 'stale from before', sent: [] as string[] };
  const ok = (body: string): UpstreamAnswer => ({ status: 200, headers: {}, body });
  const send: HeldSend = (method, path, query) => {
    const q = query?.toString() ?? '';
    b.sent.push(`${path}${q ? `?${q}` : ''}`);
    if (path === '/rr_model') return Promise.resolve(ok(JSON.stringify({ result: { reply: b.seq } })));
    if (path === '/rr_reply') {
      const t = b.buffer;
      b.buffer = '';
      return Promise.resolve(ok(t));
    }
    if (path === '/rr_gcode') return Promise.resolve(ok('{"buff":200}'));
    return Promise.resolve({ status: 404, headers: {}, body: '' });
  };
  const reply = (text: string) => {
    b.buffer += text;
    b.seq++;
  };
  return { b, send, reply };
}

let n = 0;
const replies = () =>
  new RrfReplies(Date.now, () => `00000000-0000-0000-0000-${String(++n).padStart(12, '0')}`);
const body = (a: UpstreamAnswer) =>
  JSON.parse(a.body) as {
    next: number;
    messages: string[];
    replies: Record<string, string>;
    replyTicket?: string;
  };

describe('RrfReplies (the gateway relay of a standalone board’s replies)', () => {
  it('gives each code’s reply to its ticket only, the board’s messages to every asker, each reply fetched once', async () => {
    const { b, send, reply } = board();
    const r = replies();
    const start = body(await r.ask(send, new URLSearchParams()));
    // What waited from before the gateway is nobody's.
    expect(start).toEqual({ next: 0, messages: [], replies: {} });
    const t1 = body(await r.code(send, new URLSearchParams({ gcode: 'M115' }))).replyTicket ?? '';
    reply('FIRMWARE_NAME: x');
    // Someone else's ask: no reply of the code, and the board was read once for it.
    const other = body(await r.ask(send, new URLSearchParams({ after: '0' })));
    expect(other.messages).toEqual([]);
    expect(other.replies).toEqual({});
    reply('Driver warning');
    const mine = body(
      await r.ask(
        send,
        new URLSearchParams([
          ['after', '0'],
          ['ticket', t1],
        ]),
      ),
    );
    expect(mine).toEqual({ next: 1, messages: ['Driver warning'], replies: { [t1]: 'FIRMWARE_NAME: x' } });
    expect(body(await r.ask(send, new URLSearchParams({ ticket: t1 }))).replies).toEqual({});
    expect(b.sent.filter((p) => p === '/rr_reply')).toHaveLength(3);
  });

  it('an emergency stop is sent at once (no read before it); other codes take waiting replies as messages first', async () => {
    const { b, send, reply } = board();
    const r = replies();
    await r.ask(send, new URLSearchParams());
    reply('Started printing');
    b.sent.length = 0;
    await r.code(send, new URLSearchParams({ gcode: 'M112' }));
    expect(b.sent).toEqual(['/rr_gcode?gcode=M112']);
    b.sent.length = 0;
    await r.code(send, new URLSearchParams({ gcode: 'M25' }));
    expect(b.sent.map((p) => p.split('?')[0])).toEqual(['/rr_model', '/rr_reply', '/rr_gcode']);
    expect(r.waitingCount).toBe(1);
  });
});
