import { readdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import { parseRelaxed } from './board-sim';
import { SerialLink, type PortEvents, type Reply } from './link';
import { isObject, type Json } from './protocol';

/**
 * The link against the recorded sessions (../shared/fixtures/g2core/sessions, SOURCES.md): each
 * session's host lines are written through the link (JSON requests in their lane, G-code lines,
 * and `{"gc":…}` lines which the board answers as G-code, in the line lane; controls at once),
 * and the board's lines are fed back byte for byte in the recorded order. Every request must get
 * the answer that names it, every G-code line an answer, nothing left waiting or failed.
 */

const FIX = path.resolve(__dirname, '../../../../../shared/fixtures/g2core/sessions');

async function replay(
  file: string,
): Promise<{ json: Map<string, Reply[]>; gcode: Array<Reply | Error>; sent: number }> {
  const rows = readFileSync(path.join(FIX, file), 'utf8')
    .split('\n')
    .filter((l) => l.trim() !== '')
    .map((l) => JSON.parse(l) as { dir: 'tx' | 'rx'; raw: string });
  let events: PortEvents | null = null;
  const link = new SerialLink({
    path: '/dev/replay',
    baudRate: 115200,
    bannerWaitMs: 0,
    window: 4,
    opener: {
      list: () => Promise.resolve([]),
      open: (_p, _b, e) => {
        events = e;
        return Promise.resolve({ write: () => undefined, close: () => Promise.resolve() });
      },
    },
  });
  link.start();
  for (let i = 0; i < 50 && !link.online; i++) await new Promise((r) => setTimeout(r, 5));
  expect(link.online).toBe(true);
  const json = new Map<string, Reply[]>();
  const gcode: Array<Reply | Error> = [];
  const pending: Array<Promise<unknown>> = [];
  const lines: string[] = [];
  let sent = 0;
  link.source = () => {
    const line = lines.shift();
    return line === undefined ? null : { line, done: (r) => gcode.push(r) };
  };
  for (const row of rows) {
    if (row.dir === 'rx') {
      events!.data(Buffer.from(row.raw + '\n', 'latin1'));
      continue;
    }
    const t = row.raw;
    if (t.length === 1) {
      link.control(t as '!');
      continue;
    }
    const v = t.startsWith('{') ? parseRelaxed(t) : null;
    if (isObject(v) && !('gc' in v)) {
      const [k, value] = Object.entries(v)[0]!;
      const key = k.toLowerCase();
      pending.push(
        link.request(key, value as Json).then((r) => json.set(key, [...(json.get(key) ?? []), r])),
      );
    } else {
      lines.push(t);
      sent++;
      link.pump();
    }
  }
  await Promise.all(pending);
  expect(link.linesInFlight, file).toBe(0);
  await link.stop();
  return { json, gcode, sent };
}

describe('the link against the recorded sessions', () => {
  it('matches every answer of every session to what it answers, by content', async () => {
    const files = readdirSync(FIX).filter((f) => f.endsWith('.jsonl'));
    for (const f of files) {
      const { json, gcode, sent } = await replay(f);
      expect(gcode.length, f).toBe(sent);
      for (const [key, replies] of json) {
        for (const r of replies) {
          // Named by its key, or (TinyG, an unknown name) the status 100 answer without it.
          if (Object.keys(r.r).length)
            expect(
              Object.keys(r.r).map((k) => k.toLowerCase()),
              `${f} ${key}`,
            ).toContain(key);
          else expect(r.status, `${f} ${key}`).toBe(100);
        }
      }
      for (const g of gcode) expect(g, f).not.toBeInstanceOf(Error);
    }
    const cncjs = await replay('tinyg-connect-cncjs-footer-rev3.jsonl');
    expect(cncjs.json.get('spe')?.[0]).toMatchObject({ status: 100 });
    const g0 = await replay('g0-move-filtered-sr-101.03.jsonl');
    expect(g0.gcode.length).toBeGreaterThan(0);
  });
});
