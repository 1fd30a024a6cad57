import { readFileSync } from 'node:fs';
import os from 'node:os';
import { AuditLog } from '../gateway/audit';
import { loadMachines, MachinesFileError } from '../gateway/machines';
import {
  DEFAULT_COST,
  PIN_RULE,
  PIN_RULE_TEXT,
  USER_NAME,
  dataDirPath,
  hashSecret,
  readUsers,
  updateUsers,
  usersFilePath,
  type UserRecord,
} from '../gateway/users';
import { MACHINE_ID, ROLES, type Role } from '../src/fleet/types';

/**
 * `npm run user -- <command>` manages the users file (SHOPDECK_USERS, else users.json in the
 * data folder SHOPDECK_DATA, default .shopdeck/). Creating the first user turns access control
 * on: the console stops running open.
 *
 *   add <name> --role viewer|operator|supervisor [--machines a,b] [--pin] [--password-stdin]
 *   role <name> <role>            change a user's role
 *   machines <name> a,b|all       limit a user to some machines
 *   passwd <name> [--password-stdin]
 *   pin <name> [--password-stdin] set the PIN (6 to 12 digits) a supervisor unlocks a tablet with
 *   remove <name>
 *   list
 *
 * Passwords are asked on the terminal (not echoed); with --password-stdin the first line of
 * standard input is the password and, with --pin, the second line the PIN.
 *
 * Several runs at once lose nothing: each change is made under the users file's lock on a fresh
 * read of the file, and written atomically (gateway/users.ts `updateUsers`). Passwords are asked
 * and hashed before the lock is taken, so a run waiting at a prompt holds nobody up.
 */

const USAGE = `usage: npm run user -- add <name> --role <${ROLES.join('|')}> [--machines a,b] [--pin] [--password-stdin]
       npm run user -- role <name> <role> | machines <name> <a,b|all> | passwd <name> | pin <name> | remove <name> | list`;

export class UsageError extends Error {}

function flag(args: string[], name: string): boolean {
  const i = args.indexOf(name);
  if (i < 0) return false;
  args.splice(i, 1);
  return true;
}

function option(args: string[], name: string): string | undefined {
  const i = args.indexOf(name);
  if (i < 0) return undefined;
  const v = args[i + 1];
  if (v === undefined || v.startsWith('--')) throw new UsageError(`${name} needs a value`);
  args.splice(i, 2);
  return v;
}

function parseRole(v: string | undefined): Role {
  if (!v || !(ROLES as readonly string[]).includes(v))
    throw new UsageError(`role must be one of ${ROLES.join(', ')}`);
  return v as Role;
}

/** The machine ids a user may be limited to: those of the machines file the console would load. */
export function knownMachines(env: NodeJS.ProcessEnv, cwd: string): { where: string; ids: string[] } {
  try {
    const c = loadMachines({ env, cwd });
    return {
      where: c.file ?? 'the built-in demo fleet (no machines file)',
      ids: c.machines.map((m) => m.id),
    };
  } catch (e) {
    // A machines file the server would refuse for another reason (an `env:NAME` not set in this
    // shell, say) still names its machines.
    if (e instanceof MachinesFileError) {
      const file = e.file;
      try {
        const data = JSON.parse(readFileSync(file, 'utf8')) as { machines?: Array<{ id?: unknown }> };
        const ids = (data.machines ?? [])
          .map((m) => m.id)
          .filter((id): id is string => typeof id === 'string');
        return { where: file, ids };
      } catch {
        /* unreadable: said below */
      }
    }
    throw new UsageError(`cannot read the machines file: ${e instanceof Error ? e.message : String(e)}`);
  }
}

function parseMachines(
  v: string | undefined,
  known: () => { where: string; ids: string[] },
): string[] | null {
  if (v === undefined || v === 'all') return null;
  const list = v
    .split(',')
    .map((s) => s.trim())
    .filter(Boolean);
  for (const id of list) if (!MACHINE_ID.test(id)) throw new UsageError(`"${id}" is not a machine id`);
  if (!list.length) throw new UsageError('--machines: give at least one machine id, or "all"');
  const { where, ids } = known();
  const unknown = list.filter((id) => !ids.includes(id));
  if (unknown.length)
    throw new UsageError(
      `no machine ${unknown.map((id) => `"${id}"`).join(', ')} in ${where}; ` +
        `its machines are ${ids.length ? ids.join(', ') : '(none)'}, or give "all"`,
    );
  return list;
}

let stdinLines: string[] | null = null;
async function stdinLine(index: number): Promise<string> {
  if (!stdinLines) {
    const chunks: Buffer[] = [];
    for await (const c of process.stdin) chunks.push(c as Buffer);
    stdinLines = Buffer.concat(chunks).toString('utf8').split(/\r?\n/);
  }
  return stdinLines[index] ?? '';
}

function askHidden(prompt: string): Promise<string> {
  const stdin = process.stdin;
  if (!stdin.isTTY) return Promise.reject(new UsageError('no terminal to ask on: use --password-stdin'));
  process.stderr.write(prompt);
  return new Promise((resolve, reject) => {
    let value = '';
    stdin.setRawMode(true);
    stdin.resume();
    stdin.setEncoding('utf8');
    const onData = (s: string): void => {
      for (const ch of s) {
        if (ch === '\r' || ch === '\n') {
          done();
          resolve(value);
          return;
        }
        if (ch === '\u0003') {
          done();
          reject(new UsageError('cancelled'));
          return;
        }
        if (ch === '\u007f' || ch === '\b') value = value.slice(0, -1);
        else value += ch;
      }
    };
    const done = (): void => {
      stdin.off('data', onData);
      stdin.setRawMode(false);
      stdin.pause();
      process.stderr.write('\n');
    };
    stdin.on('data', onData);
  });
}

export interface UserIo {
  /** Line `index` of the piped input (--password-stdin). */
  line(index: number): Promise<string>;
  /** Asks on the terminal without echo (default: the process's terminal). */
  ask?(prompt: string): Promise<string>;
  /** A line for the person at the terminal (default: standard error). */
  say?(text: string): void;
}

const processIo: UserIo = { line: stdinLine };

/** Wrong answers on the terminal before the script gives up. */
export const SECRET_TRIES = 3;

function secretProblem(what: 'password' | 'PIN', v: string): string | null {
  if (what === 'password' && v.length < 8) return 'the password must have at least 8 characters';
  if (what === 'PIN' && !PIN_RULE.test(v))
    return `${PIN_RULE_TEXT} (${/^\d*$/.test(v) ? `${v.length} given` : 'digits only'})`;
  return null;
}

async function readSecret(
  what: 'password' | 'PIN',
  fromStdin: boolean,
  line: number,
  io: UserIo,
): Promise<string> {
  if (fromStdin) {
    const v = await io.line(line);
    const problem = secretProblem(what, v);
    if (problem) throw new UsageError(problem);
    return v;
  }
  // On a terminal a short or mistyped secret is asked again, not the end of the run.
  const ask = io.ask ?? askHidden;
  const say = io.say ?? ((t: string) => void process.stderr.write(`${t}\n`));
  for (let tries = 1; ; tries++) {
    const v = await ask(`${what}: `);
    let problem = secretProblem(what, v);
    if (!problem && (await ask(`${what} again: `)) !== v) problem = `the two ${what}s differ`;
    if (!problem) return v;
    if (tries >= SECRET_TRIES) throw new UsageError(problem);
    say(`${problem}: try again`);
  }
}

export async function main(
  argv: string[],
  env: NodeJS.ProcessEnv = process.env,
  io: UserIo = processIo,
): Promise<string> {
  const args = [...argv];
  const cwd = process.cwd();
  const dataDir = dataDirPath({ env, cwd });
  const file = usersFilePath({ dataDir, env, cwd });
  const audit = new AuditLog(dataDir);
  const cost = Number(env.SHOPDECK_BCRYPT_COST ?? DEFAULT_COST);
  if (!Number.isInteger(cost) || cost < 4 || cost > 31)
    throw new UsageError('SHOPDECK_BCRYPT_COST must be a whole number from 4 to 31');
  // Who made a change from the command line: the OS user running the script (the audit page adds
  // "(server console)"); the user changed is named in the entry's detail.
  const by = os.userInfo().username;
  const fromStdin = flag(args, '--password-stdin');
  const withPin = flag(args, '--pin');
  const role = option(args, '--role');
  const machines = option(args, '--machines');
  const [command, name, extra] = args;
  const known = () => knownMachines(env, cwd);
  // What is on disk now: for the list, and to refuse at once (before asking for a password)
  // what cannot be done. Every change is then made under the users file's lock on a fresh read
  // (`updateUsers`: another run may have changed the file meanwhile) and checked again there.
  const users: UserRecord[] = readUsers(file) ?? [];
  const findIn = (list: UserRecord[], n: string | undefined): UserRecord => {
    const u = list.find((x) => x.name === n);
    if (!u) throw new UsageError(`no user "${n ?? ''}" in ${file}`);
    return u;
  };
  const find = (n: string | undefined): UserRecord => findIn(users, n);
  /** Changes the named user under the lock; returns the user as written. */
  const change = async (n: string | undefined, edit: (u: UserRecord) => void): Promise<UserRecord> => {
    let changed: UserRecord | null = null;
    await updateUsers(file, (list) => {
      const u = findIn(list, n);
      edit(u);
      changed = u;
      return list;
    });
    return changed ?? find(n);
  };
  const log = (
    type: 'user-added' | 'user-removed' | 'role-change' | 'password-change',
    detail: string,
    r?: Role,
  ): void => {
    audit.append({ type, result: 'ok', user: by, source: 'cli', detail, role: r });
  };
  const exists = (list: UserRecord[], n: string): void => {
    if (list.some((u) => u.name === n))
      throw new UsageError(`user "${n}" exists: use role/passwd/pin/machines`);
  };

  switch (command) {
    case 'add': {
      if (!name || !USER_NAME.test(name))
        throw new UsageError('add: give a user name (letters, digits, . _ @ -)');
      exists(users, name);
      const r = parseRole(role);
      const machineList = parseMachines(machines, known);
      const password = await readSecret('password', fromStdin, 0, io);
      const pin = withPin ? await readSecret('PIN', fromStdin, 1, io) : null;
      const u: UserRecord = {
        name,
        role: r,
        machines: machineList,
        passwordHash: await hashSecret(password, cost),
        pinHash: pin ? await hashSecret(pin, cost) : null,
      };
      const after = await updateUsers(file, (list) => {
        exists(list, name);
        return [...list, u];
      });
      log('user-added', `${name} as ${r}${u.machines ? ` for ${u.machines.join(', ')}` : ''}`, r);
      return `added ${name} (${r}) to ${file}${after.length === 1 ? '\naccess control is on: the console no longer runs open' : ''}`;
    }
    case 'role': {
      find(name);
      const r = parseRole(extra ?? role);
      let before: Role = r;
      const u = await change(name, (x) => {
        before = x.role;
        x.role = r;
      });
      log('role-change', `${u.name}: ${before} → ${r}`, r);
      return `${u.name}: ${before} → ${r}`;
    }
    case 'machines': {
      find(name);
      const list = parseMachines(extra ?? machines ?? 'all', known);
      const u = await change(name, (x) => {
        x.machines = list;
      });
      log('role-change', `${u.name}: machines ${list ? list.join(', ') : 'all'}`, u.role);
      return `${u.name}: machines ${list ? list.join(', ') : 'all'}`;
    }
    case 'passwd': {
      find(name);
      const hash = await hashSecret(await readSecret('password', fromStdin, 0, io), cost);
      const u = await change(name, (x) => {
        x.passwordHash = hash;
      });
      log('password-change', `${u.name}: password changed`);
      return `${u.name}: password changed`;
    }
    case 'pin': {
      find(name);
      const hash = await hashSecret(await readSecret('PIN', fromStdin, 0, io), cost);
      const u = await change(name, (x) => {
        x.pinHash = hash;
      });
      log('password-change', `${u.name}: PIN set`);
      return `${u.name}: PIN set${u.role === 'supervisor' ? '' : ' (only a supervisor PIN unlocks a tablet)'}`;
    }
    case 'remove': {
      find(name);
      let removed: UserRecord | null = null;
      const after = await updateUsers(file, (list) => {
        const u = findIn(list, name);
        removed = u;
        return list.filter((x) => x !== u);
      });
      const u = removed ?? find(name);
      log('user-removed', `${u.name} (was ${u.role})`, u.role);
      return `removed ${u.name}${after.length === 0 ? ' (no users left: nobody can log in; delete the file to run open)' : ''}`;
    }
    case 'list': {
      if (!users.length) return `no users in ${file}: the console runs open`;
      return users
        .map(
          (u) =>
            `${u.name.padEnd(20)} ${u.role.padEnd(10)} ${u.machines ? u.machines.join(',') : 'all machines'}${u.pinHash ? '  (PIN)' : ''}`,
        )
        .join('\n');
    }
    default:
      throw new UsageError(USAGE);
  }
}

const isMain = process.argv[1] && /user\.ts$/.test(process.argv[1]);
if (isMain) {
  main(process.argv.slice(2))
    .then((out) => {
      console.log(out);
      process.exit(0);
    })
    .catch((e: unknown) => {
      console.error(e instanceof Error ? e.message : String(e));
      process.exit(e instanceof UsageError ? 2 : 1);
    });
}
