import { existsSync, readFileSync, readdirSync, statSync, writeFileSync } from 'node:fs';
import type { FileHandle } from 'node:fs/promises';
import * as fsp from 'node:fs/promises';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { AuditLog, auditMatcher, type AuditEntry, type AuditFs, type AuditQuery } from './audit';
import { createLogger, type Logger } from './log';
import type { MachineEntry } from './machines';
import { consoleFetch, startGateway, startStub, tempDir, testFamily } from './test-util';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function dir(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return t.dir;
}

function captured(): { log: Logger; lines: string[] } {
  const lines: string[] = [];
  return { log: createLogger({ json: true, write: (l) => lines.push(l) }), lines };
}

function queued(d: string, opts: ConstructorParameters<typeof AuditLog>[1] = {}): AuditLog {
  const a = new AuditLog(d, { writer: 'queue', log: captured().log, ...opts });
  cleanups.push(() => a.close());
  return a;
}

/** Entry n: machine a or b, user u<n mod 3>, result ok or error, time n seconds after midnight. */
function entry(n: number): Omit<AuditEntry, 'time'> & { time: string } {
  return {
    time: new Date(Date.UTC(2026, 2, 1, 0, 0, n)).toISOString(),
    type: 'command',
    result: n % 4 === 0 ? 'error' : 'ok',
    user: `u${n % 3}`,
    source: 'gateway',
    machine: n % 2 ? 'a' : 'b',
    detail: `#${n}`,
  };
}

/** What is on disk, oldest first: `audit.<keep-1>.jsonl` … `audit.jsonl`. */
function onDisk(d: string): AuditEntry[] {
  const files = readdirSync(d)
    .map((f) => /^audit(?:\.(\d+))?\.jsonl$/.exec(f))
    .filter((m): m is RegExpExecArray => m !== null)
    .sort((x, y) => Number(y[1] ?? 0) - Number(x[1] ?? 0));
  return files.flatMap((m) =>
    readFileSync(path.join(d, m[0]), 'utf8')
      .split('\n')
      .filter(Boolean)
      .map((l) => JSON.parse(l) as AuditEntry),
  );
}

const details = (es: readonly AuditEntry[]): string[] => es.map((e) => e.detail ?? '');

/** The reference answer: every entry filtered, newest first, sliced as `query` pages. */
function expected(all: readonly AuditEntry[], q: AuditQuery): { entries: string[]; total: number } {
  const list = all.filter(auditMatcher(q)).reverse();
  const offset = q.offset ?? 0;
  return { entries: details(list.slice(offset, offset + (q.limit ?? 50))), total: list.length };
}

/** A file system whose handles record what they do (and may hold writes back). */
function recordingFs(opts: { delay?: () => number; gate?: Promise<void> } = {}): {
  fs: AuditFs;
  ops: string[];
} {
  const ops: string[] = [];
  const fs: AuditFs = {
    ...fsp,
    open: (async (...args: Parameters<typeof fsp.open>) => {
      const fh = await fsp.open(...args);
      if (args[1] !== 'a+') return fh;
      const write = fh.write.bind(fh) as (
        b: Buffer,
        o: number,
        l: number,
      ) => Promise<{ bytesWritten: number }>;
      const sync = fh.sync.bind(fh);
      return Object.assign(Object.create(fh) as FileHandle, {
        write: async (b: Buffer, o: number, l: number) => {
          if (opts.gate) await opts.gate;
          const ms = opts.delay?.() ?? 0;
          if (ms) await new Promise((r) => setTimeout(r, ms));
          const r = await write(b, o, l);
          ops.push(
            `write ${b
              .subarray(o, o + r.bytesWritten)
              .toString('utf8')
              .trim()}`,
          );
          return r;
        },
        sync: async () => {
          await sync();
          ops.push('sync');
        },
        close: () => fh.close(),
        stat: () => fh.stat(),
        read: fh.read.bind(fh),
      });
    }) as AuditFs['open'],
  };
  return { fs, ops };
}

describe('audit log: rotation', () => {
  it('keeps N files of at most maxBytes, and queries span them newest first', async () => {
    const d = dir();
    const a = queued(d, { maxBytes: 700, keep: 3, indexSize: 5 });
    for (let n = 0; n < 60; n++) a.append(entry(n));
    await a.flush();
    const names = readdirSync(d).sort();
    expect(names).toEqual(['audit.1.jsonl', 'audit.2.jsonl', 'audit.jsonl']);
    for (const f of names) expect(statSync(path.join(d, f)).size).toBeLessThanOrEqual(700);
    // What is left is the newest entries, in order, without a gap.
    const kept = onDisk(d);
    const first = Number(kept[0]?.detail?.slice(1));
    expect(first).toBeGreaterThan(0);
    expect(details(kept)).toEqual(Array.from({ length: 60 - first }, (_, i) => `#${first + i}`));

    // Pages newest first across the three files (only 5 entries are in memory), with filters.
    const queries: AuditQuery[] = [
      { limit: 4 },
      { offset: 4, limit: 7 },
      { offset: 12, limit: 50 },
      { offset: kept.length - 2, limit: 5 },
      { machine: 'a', offset: 3, limit: 6 },
      { user: 'u1', result: 'ok', offset: 2, limit: 3 },
      { from: Date.parse(kept[3]!.time), to: Date.parse(kept[9]!.time), limit: 50 },
    ];
    for (const q of queries) {
      const r = await a.query(q);
      expect({ entries: details(r.entries), total: r.total }, JSON.stringify(q)).toEqual(expected(kept, q));
    }
    expect(details(await a.filtered({ machine: 'b' }))).toEqual(
      details(kept.filter((e) => e.machine === 'b').reverse()),
    );

    // A restart loads the newest entries from the end of the files and answers the same.
    const again = queued(d, { maxBytes: 700, keep: 3, indexSize: 5 });
    for (const q of queries) {
      const r = await again.query(q);
      expect({ entries: details(r.entries), total: r.total }).toEqual(expected(kept, q));
    }
    expect(details(again.all())).toEqual(details(kept));
  });

  it('keeps totals right while entries leave memory and files are rotated away', async () => {
    const d = dir();
    const a = queued(d, { maxBytes: 900, keep: 4, indexSize: 3 });
    const q: AuditQuery = { machine: 'a', limit: 2 };
    for (let n = 0; n < 10; n++) a.append(entry(n));
    expect((await a.query(q)).total).toBe(5);
    for (let n = 10; n < 200; n++) {
      a.append(entry(n));
      if (n % 7 === 0) {
        const r = await a.query(q);
        await a.flush();
        expect({ entries: details(r.entries), total: r.total }, `after #${n}`).toEqual(
          expected(onDisk(d), q),
        );
      }
    }
    expect(readdirSync(d).sort()).toEqual(['audit.1.jsonl', 'audit.2.jsonl', 'audit.3.jsonl', 'audit.jsonl']);
  });

  it('SHOPDECK_AUDIT_MAX_BYTES and SHOPDECK_AUDIT_KEEP set the gateway’s rotation', async () => {
    const d = dir();
    const gw = await startGateway({
      machines: { file: null, machines: [] },
      families: {},
      dataDir: d,
      env: { SHOPDECK_AUDIT_MAX_BYTES: '400', SHOPDECK_AUDIT_KEEP: '2' },
      log: captured().log,
    });
    cleanups.push(gw.close);
    for (let n = 0; n < 20; n++) gw.gw.audit.append(entry(n));
    await gw.gw.audit.flush();
    expect(
      readdirSync(d)
        .filter((f) => f.startsWith('audit'))
        .sort(),
    ).toEqual(['audit.1.jsonl', 'audit.jsonl']);
    expect(statSync(path.join(d, 'audit.jsonl')).size).toBeLessThanOrEqual(400);
  });
});

describe('audit log: crashes', () => {
  it('loads a log whose last line was cut by a crash, with one warning, and writes on a new line', async () => {
    const d = dir();
    const lines = [entry(1), entry(2), entry(3)].map((e) => JSON.stringify(e));
    writeFileSync(path.join(d, 'audit.1.jsonl'), JSON.stringify(entry(0)) + '\n');
    writeFileSync(path.join(d, 'audit.jsonl'), lines.join('\n') + '\n' + lines[2]!.slice(0, 25));
    const { log, lines: logged } = captured();
    const a = queued(d, { log });
    expect(details(a.all())).toEqual(['#0', '#1', '#2', '#3']);
    expect(logged).toHaveLength(1);
    expect(JSON.parse(logged[0]!)).toMatchObject({ level: 'warn', msg: expect.stringMatching(/incomplete/) });
    a.append(entry(4));
    await a.flush();
    const text = readFileSync(path.join(d, 'audit.jsonl'), 'utf8');
    expect(text.endsWith(`\n${JSON.stringify(entry(4))}\n`)).toBe(true);
    // Restarted: the torn line is now a line of its own, skipped; nothing else is lost.
    const again = new AuditLog(d, { log: captured().log });
    expect(details(again.all())).toEqual(['#0', '#1', '#2', '#3', '#4']);
    expect((await again.query({ limit: 2 })).entries.map((e) => e.detail)).toEqual(['#4', '#3']);
  });

  it('reads lines longer than its read chunk and multi-byte text split across chunks', async () => {
    const d = dir();
    const long = { ...entry(1), detail: 'ü€'.repeat(40_000) };
    writeFileSync(
      path.join(d, 'audit.jsonl'),
      [entry(0), long, entry(2)].map((e) => JSON.stringify(e)).join('\n') + '\n',
    );
    const a = queued(d, { indexSize: 1 });
    const r = await a.query({ offset: 1, limit: 5 });
    expect(r.total).toBe(3);
    expect(r.entries.map((e) => e.detail)).toEqual([long.detail, '#0']);
  });
});

describe('audit log: writing', () => {
  it('keeps the order of many appends made at once (writes held back at random)', async () => {
    const d = dir();
    const { fs } = recordingFs({ delay: () => (Math.random() < 0.3 ? Math.floor(Math.random() * 4) : 0) });
    const a = queued(d, { fs, maxBytes: 20_000, keep: 100 });
    const order: string[] = [];
    await Promise.all(
      Array.from({ length: 40 }, async (_, worker) => {
        for (let i = 0; i < 25; i++) {
          await new Promise((r) => setImmediate(r));
          const e = a.append({ ...entry(i), detail: `${worker}.${i}` });
          order.push(e.detail ?? '');
        }
      }),
    );
    await a.flush();
    expect(details(onDisk(d))).toEqual(order);
    expect(details(a.all())).toEqual(order);
    expect(readdirSync(d).length).toBeGreaterThan(3); // rotated on the way
  });

  it('fsyncs a batch that holds a command right after writing it; session ends ride along', async () => {
    const d = dir();
    const { fs, ops } = recordingFs();
    const a = queued(d, { fs });
    a.append({ type: 'logout', result: 'ok', user: 'ana', source: 'gateway' });
    await waitFor(() => ops.length === 1);
    await new Promise((r) => setTimeout(r, 20));
    expect(ops).toEqual([expect.stringMatching(/"logout"/)]);
    a.append({ ...entry(1), detail: 'cmd' });
    await waitFor(() => ops.length === 3);
    expect(ops.slice(1)).toEqual([expect.stringMatching(/"detail":"cmd"/), 'sync']);
    // A burst is written as one batch with one fsync.
    a.append({ ...entry(2), detail: 'x' });
    a.append({ ...entry(3), detail: 'y' });
    await waitFor(() => ops.length === 5);
    expect(ops.slice(3)).toEqual([expect.stringMatching(/"x"[^]*\n[^]*"y"/), 'sync']);
  });

  it('fsyncs the command entries of proxied requests (the gateway’s writer)', async () => {
    const d = dir();
    const { fs, ops } = recordingFs();
    const s = await startStub();
    cleanups.push(s.close);
    const m: MachineEntry = {
      id: 'p1',
      name: 'p1',
      kind: 'prunt',
      simulated: false,
      url: new URL(s.url),
      wsUrl: null,
      secrets: {},
    };
    const gw = await startGateway({
      machines: { file: null, machines: [m] },
      families: { prunt: testFamily('prunt') },
      dataDir: d,
      env: {},
      audit: { fs },
      log: captured().log,
    });
    cleanups.push(gw.close);
    const r = await consoleFetch(`${gw.url}/machines/p1/job?action=pause`, {
      headers: { 'X-Shopdeck-Command': 'test.pause' },
    });
    expect(r.status).toBe(200);
    await waitFor(() => ops.includes('sync'));
    const i = ops.findIndex((o) => o.includes('"commandId":"test.pause"'));
    expect(i).toBeGreaterThanOrEqual(0);
    expect(ops[i + 1]).toBe('sync');
  });

  it('flush() waits for the writes under way and makes them durable', async () => {
    const d = dir();
    let open!: () => void;
    const gate = new Promise<void>((r) => (open = r));
    const { fs, ops } = recordingFs({ gate });
    const a = queued(d, { fs });
    for (const n of [1, 2, 3]) a.append({ ...entry(n), type: 'logout' });
    let flushed = false;
    const f = a.flush().then(() => (flushed = true));
    await new Promise((r) => setTimeout(r, 30));
    expect(flushed).toBe(false);
    expect(
      existsSync(path.join(d, 'audit.jsonl')) ? readFileSync(path.join(d, 'audit.jsonl'), 'utf8') : '',
    ).toBe('');
    // Queries do not wait for the disk to see what was appended.
    expect(details(a.all())).toEqual(['#1', '#2', '#3']);
    open();
    await f;
    expect(details(onDisk(d))).toEqual(['#1', '#2', '#3']);
    expect(ops.at(-1)).toBe('sync');
  });

  it('after close(), entries are written at once (a request that ends during shutdown)', async () => {
    const d = dir();
    const a = queued(d);
    a.append(entry(1));
    await a.close();
    a.append(entry(2));
    expect(details(onDisk(d))).toEqual(['#1', '#2']);
    expect(details(a.all())).toEqual(['#1', '#2']);
  });

  it('sees entries another process appended (npm run user) and keeps writing after them', async () => {
    const d = dir();
    const a = queued(d, { indexSize: 2 });
    a.append(entry(1));
    a.append(entry(2));
    await a.flush();
    const cli = new AuditLog(d); // direct: `npm run user`
    cli.append({ ...entry(3), source: 'cli', type: 'role-change' });
    expect((await a.query({ limit: 1 })).entries[0]).toMatchObject({ detail: '#3', source: 'cli' });
    a.append(entry(4));
    await a.flush();
    expect(details(onDisk(d))).toEqual(['#1', '#2', '#3', '#4']);
    const r = await a.query({ offset: 1, limit: 10 });
    expect({ entries: details(r.entries), total: r.total }).toEqual({
      entries: ['#3', '#2', '#1'],
      total: 4,
    });
  });
});

async function waitFor(ok: () => boolean, ms = 2000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error('timed out waiting');
    await new Promise((r) => setTimeout(r, 2));
  }
}
