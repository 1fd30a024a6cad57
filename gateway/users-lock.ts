import { closeSync, mkdirSync, openSync, readFileSync, statSync, unlinkSync, writeSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { randomBytes } from 'node:crypto';

/**
 * The users file's lock (`npm run user` runs may overlap): every change is a read-modify-write
 * under `<users file>.lock`, created with O_EXCL and holding `{pid, host, at, nonce}`. A stale
 * lock (process gone on this host, older than `staleMs`, or empty and older than 2 s) is broken
 * under a second O_EXCL file (`.lock.break`); a holder removes only its own (gateway/README.md).
 */

export class UsersFileLockedError extends Error {
  constructor(
    readonly lockFile: string,
    holder: string,
  ) {
    super(
      `the users file is locked by ${holder} (${lockFile}): another "npm run user" is changing it. ` +
        `Try again; if none is running, delete ${lockFile}`,
    );
    this.name = 'UsersFileLockedError';
  }
}

export interface FileLockOptions {
  /** Give up waiting for the lock after this long (default 10 s). */
  timeoutMs?: number;
  /** A lock older than this is stale whoever holds it (default 30 s). */
  staleMs?: number;
  /** Between tries (default 25 ms, plus up to as much again at random). */
  retryMs?: number;
}

interface LockInfo {
  content: string;
  ageMs: number;
  pid: number | null;
  host: string | null;
}

function readLock(lock: string): LockInfo | null {
  try {
    const st = statSync(lock);
    const content = readFileSync(lock, 'utf8');
    let pid: number | null = null;
    let host: string | null = null;
    try {
      const v = JSON.parse(content) as { pid?: unknown; host?: unknown };
      if (typeof v.pid === 'number' && Number.isInteger(v.pid) && v.pid > 0) pid = v.pid;
      if (typeof v.host === 'string') host = v.host;
    } catch {
      // empty or torn: judged by its age
    }
    return { content, ageMs: Date.now() - st.mtimeMs, pid, host };
  } catch (e) {
    if ((e as NodeJS.ErrnoException).code === 'ENOENT') return null;
    throw e;
  }
}

function processGone(pid: number): boolean {
  try {
    process.kill(pid, 0);
    return false;
  } catch (e) {
    return (e as NodeJS.ErrnoException).code === 'ESRCH';
  }
}

function isStale(l: LockInfo, staleMs: number): boolean {
  if (l.ageMs > staleMs) return true;
  if (l.pid === null) return l.ageMs > 2000;
  return l.host === os.hostname() && l.pid !== process.pid && processGone(l.pid);
}

/** Removes `lock` if it is (still) the stale one seen; true when the caller should try again at once. */
function breakStale(lock: string, seen: LockInfo, staleMs: number): boolean {
  const breaker = `${lock}.break`;
  try {
    closeSync(openSync(breaker, 'wx', 0o600));
  } catch (e) {
    if ((e as NodeJS.ErrnoException).code !== 'EEXIST') throw e;
    // Someone else is breaking it; a breaker left by a killed process goes after 10 s.
    try {
      if (Date.now() - statSync(breaker).mtimeMs > 10_000) unlinkSync(breaker);
    } catch {
      // gone meanwhile
    }
    return false;
  }
  try {
    const again = readLock(lock);
    if (again && again.content === seen.content && isStale(again, staleMs)) unlinkSync(lock);
    return true;
  } finally {
    unlinkSync(breaker);
  }
}

const pause = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

/** Runs `fn` holding the exclusive lock of `file` (`<file>.lock`); see above. */
export async function withFileLock<T>(
  file: string,
  fn: () => T | Promise<T>,
  opts: FileLockOptions = {},
): Promise<T> {
  const timeoutMs = opts.timeoutMs ?? 10_000;
  const staleMs = opts.staleMs ?? 30_000;
  const retryMs = opts.retryMs ?? 25;
  const lock = `${file}.lock`;
  mkdirSync(path.dirname(file), { recursive: true });
  const mine = JSON.stringify({
    pid: process.pid,
    host: os.hostname(),
    at: new Date().toISOString(),
    nonce: randomBytes(8).toString('hex'),
  });
  const deadline = Date.now() + timeoutMs;
  for (;;) {
    try {
      const fd = openSync(lock, 'wx', 0o600);
      try {
        writeSync(fd, mine);
      } finally {
        closeSync(fd);
      }
      break;
    } catch (e) {
      if ((e as NodeJS.ErrnoException).code !== 'EEXIST') throw e;
    }
    const held = readLock(lock);
    if (!held) continue; // released meanwhile
    if (isStale(held, staleMs) && breakStale(lock, held, staleMs)) continue;
    if (Date.now() >= deadline) {
      const who =
        held.pid !== null ? `process ${held.pid}${held.host ? ` on ${held.host}` : ''}` : 'a process';
      throw new UsersFileLockedError(lock, who);
    }
    await pause(retryMs + Math.random() * retryMs);
  }
  try {
    return await fn();
  } finally {
    // Only our own lock: never one another process made after ours was (wrongly) broken.
    if (readLock(lock)?.content === mine) unlinkSync(lock);
  }
}
