import { spawn, type ChildProcess } from 'node:child_process';
import { writeFileSync } from 'node:fs';
import { createServer } from 'node:net';
import { expect, type Browser, type Page } from '@playwright/test';
import bcrypt from 'bcryptjs';

/**
 * For specs that run a console of their own (a users file, their own machines, their own
 * environment) beside the shared one of playwright.config.ts: a free port, a child process in its
 * own process group, and a wait until it answers.
 */

export function freePort(): Promise<number> {
  return new Promise((resolve) => {
    const s = createServer();
    s.listen(0, '127.0.0.1', () => {
      const p = (s.address() as { port: number }).port;
      s.close(() => resolve(p));
    });
  });
}

export async function waitFor(url: string, what: string): Promise<void> {
  for (let i = 0; i < 240; i++) {
    try {
      const r = await fetch(url);
      if (r.status < 500) return;
    } catch {
      // not up yet
    }
    await new Promise((r) => setTimeout(r, 250));
  }
  throw new Error(`${what} did not start`);
}

/** Node children started by a spec; `stopAll` ends them and what they started. */
export class Children {
  private readonly list: ChildProcess[] = [];

  /** A Node child in its own process group, so that stopping it stops everything it started. */
  start(args: string[], env: NodeJS.ProcessEnv): ChildProcess {
    const c = spawn(process.execPath, args, {
      env: { ...process.env, ...env },
      stdio: ['ignore', 'pipe', 'pipe'],
      detached: true,
    });
    c.stdout?.resume();
    c.stderr?.resume();
    this.list.push(c);
    return c;
  }

  stopAll(): void {
    for (const c of this.list.splice(0)) {
      if (c.pid && c.exitCode === null) {
        try {
          process.kill(-c.pid, 'SIGTERM');
        } catch {
          c.kill('SIGTERM');
        }
      }
    }
  }
}

/** A users file for the spec's own console: every user may use every machine. */
export function writeUsersFile(
  file: string,
  users: Readonly<Record<string, { role: string; password: string }>>,
): void {
  writeFileSync(
    file,
    JSON.stringify({
      users: Object.entries(users).map(([name, u]) => ({
        name,
        role: u.role,
        machines: null,
        passwordHash: bcrypt.hashSync(u.password, 4),
      })),
    }),
  );
}

/**
 * Signs a user in on a new browser context of the spec's own console at `path` (its login form),
 * and waits for the reload that signing in makes, so that a `goto` right after does not race it.
 */
export async function signIn(
  browser: Browser,
  base: string,
  name: string,
  user: { role: string; password: string },
  path = '/',
): Promise<Page> {
  const ctx = await browser.newContext({ baseURL: base });
  const page = await ctx.newPage();
  await page.goto(path);
  await expect(page.getByTestId('login-form')).toBeVisible();
  await expect(page.getByTestId('open-mode-banner')).toHaveCount(0);
  await page.getByLabel('Name').fill(name);
  await page.getByLabel('Password').fill(user.password);
  const reloaded = page.waitForEvent('load');
  await page.getByRole('button', { name: 'Sign in' }).click();
  await reloaded;
  await expect(page.getByTestId('user-role')).toHaveText(user.role);
  return page;
}
