import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import Database from 'better-sqlite3';
import { afterEach, describe, expect, it } from 'vitest';
import { type Migration, migrate, openHistoryDb, schemaVersion } from './db';

const dirs: string[] = [];
afterEach(() => {
  for (const d of dirs.splice(0)) rmSync(d, { recursive: true, force: true });
});

const TWO: Migration[] = [
  { name: 'one', sql: 'CREATE TABLE one (x INTEGER)' },
  { name: 'two', sql: 'CREATE TABLE two (x INTEGER)' },
];

describe('migrations when two processes open the same file at once', () => {
  it('a migration applied by the other process between our read of the version and our lock is not run again', () => {
    const dir = mkdtempSync(join(tmpdir(), 'shopdeck-db-'));
    dirs.push(dir);
    const file = join(dir, 'history.sqlite');
    const ours = new Database(file);
    ours.pragma('journal_mode = WAL');
    let raced = false;
    // The other process migrates the file at the moment ours has read version 0 and is about to
    // take the write lock (when it first looks up a migration).
    const racing = new Proxy(TWO, {
      get(target, prop, receiver) {
        if (prop === '0' && !raced) {
          raced = true;
          openHistoryDb(file, TWO).db.close();
        }
        return Reflect.get(target, prop, receiver) as unknown;
      },
    });
    const applied = migrate(ours, racing);
    expect(raced).toBe(true);
    expect(applied).toEqual([]);
    expect(schemaVersion(ours)).toBe(2);
    ours.close();
  });

  it('still applies every migration on a new file', () => {
    const dir = mkdtempSync(join(tmpdir(), 'shopdeck-db-'));
    dirs.push(dir);
    const { db, applied } = openHistoryDb(join(dir, 'history.sqlite'), TWO);
    expect(applied).toEqual(['one', 'two']);
    expect(schemaVersion(db)).toBe(2);
    db.close();
  });
});
