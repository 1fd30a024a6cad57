import { existsSync, mkdirSync, readFileSync, renameSync, statSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { randomBytes } from 'node:crypto';
import bcrypt from 'bcryptjs';
import { z } from 'zod';
import { MACHINE_ID, ROLES, type Role } from '../src/fleet/types';
import { loggerFromEnv, type Logger } from './log';

/**
 * The users file (`SHOPDECK_USERS`, else `users.json` in the data folder). With no users file
 * the console runs open. Passwords and PINs are bcrypt hashes; the file is written 0600.
 *
 * ```json
 * { "users": [ { "name": "ana", "role": "operator", "machines": ["laser-1"],
 *                "passwordHash": "$2b$12$…", "pinHash": "$2b$12$…" } ] }
 * ```
 */

export const USER_NAME = /^[A-Za-z0-9._@-]{1,64}$/;

/** A supervisor's PIN: 6 to 12 digits (`npm run user`; the gateway does not evaluate others). */
export const PIN_RULE = /^\d{6,12}$/;
export const PIN_RULE_TEXT = 'the PIN must be 6 to 12 digits';

/** bcrypt cost of new hashes (`SHOPDECK_BCRYPT_COST` for `npm run user`). */
export const DEFAULT_COST = 12;

const userSchema = z.strictObject({
  name: z.string().regex(USER_NAME, 'must be 1 to 64 of A-Z, a-z, 0-9 and . _ @ -'),
  role: z.enum(ROLES),
  machines: z.array(z.string().regex(MACHINE_ID, 'not a machine id')).nullable().optional(),
  passwordHash: z.string().regex(/^\$2[aby]\$\d\d\$/, 'not a bcrypt hash'),
  pinHash: z
    .string()
    .regex(/^\$2[aby]\$\d\d\$/, 'not a bcrypt hash')
    .nullable()
    .optional(),
});

const usersFileSchema = z.strictObject({ users: z.array(userSchema) });

export interface UserRecord {
  name: string;
  role: Role;
  /** null: every machine */
  machines: string[] | null;
  passwordHash: string;
  pinHash: string | null;
}

export class UsersFileError extends Error {
  constructor(
    readonly file: string,
    problem: string,
  ) {
    super(`Shopdeck: the users file ${file} is not valid: ${problem}`);
    this.name = 'UsersFileError';
  }
}

export function usersFilePath(opts: {
  usersFile?: string;
  dataDir: string;
  env: NodeJS.ProcessEnv;
  cwd: string;
}): string {
  const f = opts.usersFile ?? opts.env.SHOPDECK_USERS;
  return f ? path.resolve(opts.cwd, f) : path.join(opts.dataDir, 'users.json');
}

export function dataDirPath(opts: { dataDir?: string; env: NodeJS.ProcessEnv; cwd: string }): string {
  return path.resolve(opts.cwd, opts.dataDir ?? opts.env.SHOPDECK_DATA ?? '.shopdeck');
}

/** Reads the users file; null when it does not exist (open mode). */
export function readUsers(file: string): UserRecord[] | null {
  if (!existsSync(file)) return null;
  let data: unknown;
  try {
    data = JSON.parse(readFileSync(file, 'utf8')) as unknown;
  } catch (e) {
    throw new UsersFileError(file, `not readable JSON: ${e instanceof Error ? e.message : String(e)}`);
  }
  const r = usersFileSchema.safeParse(data);
  if (!r.success) {
    const i = r.error.issues[0];
    throw new UsersFileError(file, i ? `field "${i.path.join('.')}": ${i.message}` : 'invalid');
  }
  const seen = new Set<string>();
  for (const u of r.data.users) {
    if (seen.has(u.name)) throw new UsersFileError(file, `duplicate user "${u.name}"`);
    seen.add(u.name);
  }
  return r.data.users.map((u) => ({
    name: u.name,
    role: u.role,
    machines: u.machines ?? null,
    passwordHash: u.passwordHash,
    pinHash: u.pinHash ?? null,
  }));
}

export function writeUsers(file: string, users: readonly UserRecord[]): void {
  mkdirSync(path.dirname(file), { recursive: true });
  const tmp = `${file}.${process.pid}.tmp`;
  writeFileSync(tmp, JSON.stringify({ users }, null, 2) + '\n', { mode: 0o600 });
  renameSync(tmp, file);
}

export function hashSecret(secret: string, cost = DEFAULT_COST): Promise<string> {
  return bcrypt.hash(secret, cost);
}

/** The cost parameter of a bcrypt hash (`$2b$12$…` → 12), or null. */
export function bcryptCost(hash: string): number | null {
  const m = /^\$2[aby]\$(\d\d)\$/.exec(hash);
  return m ? Number(m[1]) : null;
}

/** The most common cost among `hashes` (the higher on a tie), or null when there is none. */
function usualCost(hashes: ReadonlyArray<string | null>): number | null {
  const counts = new Map<number, number>();
  for (const h of hashes) {
    const c = h ? bcryptCost(h) : null;
    if (c !== null) counts.set(c, (counts.get(c) ?? 0) + 1);
  }
  let best: number | null = null;
  for (const [c, n] of counts) {
    const bestN = best === null ? 0 : (counts.get(best) ?? 0);
    if (best === null || n > bestN || (n === bestN && c > best)) best = c;
  }
  return best;
}

const dummies = new Map<number, string>();
/**
 * A well-formed bcrypt hash of a random secret with the given cost: comparing against it costs
 * exactly what comparing against a real hash of that cost does. Made cheaply at cost 4, then
 * given the cost (the cost field only says how many rounds the comparison runs).
 */
function dummyWithCost(cost: number): string {
  let d = dummies.get(cost);
  if (!d) {
    const base = bcrypt.hashSync(randomBytes(16).toString('hex'), 4);
    d = base.replace(/^(\$2[aby]\$)\d\d\$/, `$1${String(cost).padStart(2, '0')}$`);
    dummies.set(cost, d);
  }
  return d;
}

export function checkSecret(secret: string, hash: string): Promise<boolean> {
  return bcrypt.compare(secret, hash);
}

/**
 * The users file as the gateway sees it: re-read when it changes on disk, so `npm run user`
 * takes effect without a restart. Once secured, a users file that disappears or breaks does
 * not open the console: it stays secured (and nobody can log in) until the file is fixed.
 */
export class UserDirectory {
  private users: UserRecord[] | null;
  private stamp: string;
  private secured: boolean;
  private gen = 0;

  constructor(
    readonly file: string,
    private readonly log: Logger = loggerFromEnv(),
  ) {
    this.users = readUsers(file);
    this.secured = this.users !== null;
    this.stamp = this.currentStamp();
  }

  private currentStamp(): string {
    try {
      const s = statSync(this.file);
      return `${s.mtimeMs}:${s.size}:${s.ino}`;
    } catch {
      return 'missing';
    }
  }

  private refresh(): void {
    const stamp = this.currentStamp();
    if (stamp === this.stamp) return;
    this.stamp = stamp;
    this.gen++;
    try {
      const users = readUsers(this.file);
      if (users) {
        this.users = users;
        this.secured = true;
      } else if (this.secured) {
        this.users = [];
      }
    } catch (e) {
      this.log.error(e instanceof Error ? e.message : String(e), { file: this.file });
      if (this.secured) this.users = [];
    }
  }

  get mode(): 'open' | 'secured' {
    this.refresh();
    return this.secured ? 'secured' : 'open';
  }

  find(name: string): UserRecord | null {
    this.refresh();
    return this.users?.find((u) => u.name === name) ?? null;
  }

  /** Goes up each time the users file changed on disk (re-read), so sessions can be re-checked. */
  get generation(): number {
    this.refresh();
    return this.gen;
  }

  /**
   * The hash to compare against when there is no real one (unknown user, not a supervisor, no
   * PIN): with the cost of the users' hashes of that kind (PINs: else of the passwords), else
   * `hashSecret`'s default, so that the answer takes as long as for a real user.
   */
  dummyHash(kind: 'password' | 'pin'): string {
    this.refresh();
    const list = this.users ?? [];
    const cost =
      (kind === 'pin' ? usualCost(list.map((u) => u.pinHash)) : null) ??
      usualCost(list.map((u) => u.passwordHash)) ??
      DEFAULT_COST;
    return dummyWithCost(cost);
  }
}
