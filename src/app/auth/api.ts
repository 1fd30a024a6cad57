import { z } from 'zod/mini';
import { createStore } from 'zustand/vanilla';
import { authStore, onSessionGone } from '../../fleet/auth';
import { ROLES } from '../../fleet/types';
import { CONSOLE_HEADERS } from '../../fleet/origin';

/**
 * The browser side of the gateway's access control: session, login, logout, PIN elevation.
 * Results go into `authStore` (src/fleet/auth.ts), which decides what the UI hides and
 * disables; the gateway enforces the same roles on every request.
 */

const UserSchema = z.object({
  name: z.string(),
  role: z.enum(ROLES),
  machines: z.nullable(z.array(z.string())),
});

export const SessionSchema = z.object({
  mode: z.enum(['open', 'secured']),
  /** Open mode on the network (SHOPDECK_OPEN=1), not only on this computer. */
  openOnNetwork: z.optional(z.boolean()),
  user: z.nullable(UserSchema),
  idleTimeoutS: z.optional(z.nullable(z.number())),
  elevation: z.optional(
    z.nullable(z.object({ supervisor: z.string(), until: z.string(), operator: UserSchema })),
  ),
  expired: z.optional(z.boolean()),
});

export type SessionInfo = z.infer<typeof SessionSchema>;

export interface SessionExtra {
  idleTimeoutS: number | null;
  /** A supervisor unlocked this (operator's) tablet with a PIN until `until` (ms). */
  elevation: { supervisor: string; until: number; operator: string } | null;
  /** The last session ended by the idle timeout. */
  expired: boolean;
  /** This store has been filled from the gateway at least once. */
  loaded: boolean;
  /** The session this page was signed in with ended while the page was open ("Signed out — sign in again"). */
  signedOut: boolean;
}

/** What `authStore` has no room for. */
export const sessionExtra = createStore<SessionExtra>(() => ({
  idleTimeoutS: null,
  elevation: null,
  expired: false,
  loaded: false,
  signedOut: false,
}));

export class AuthError extends Error {
  constructor(
    message: string,
    readonly status: number,
    readonly retryAfterS: number | null = null,
  ) {
    super(message);
    this.name = 'AuthError';
  }
}

let elevationTimer: ReturnType<typeof setTimeout> | null = null;

function apply(s: SessionInfo): SessionInfo {
  authStore.setState({ mode: s.mode, user: s.user, openOnNetwork: s.openOnNetwork === true });
  const until = s.elevation ? Date.parse(s.elevation.until) : NaN;
  sessionExtra.setState({
    idleTimeoutS: s.idleTimeoutS ?? null,
    elevation:
      s.elevation && Number.isFinite(until)
        ? { supervisor: s.elevation.supervisor, until, operator: s.elevation.operator.name }
        : null,
    expired: s.expired ?? false,
    loaded: true,
    ...(s.user ? { signedOut: false } : {}),
  });
  // When the elevation runs out the gateway falls back to the operator: follow it.
  if (elevationTimer) clearTimeout(elevationTimer);
  elevationTimer = null;
  if (Number.isFinite(until)) {
    elevationTimer = setTimeout(
      () => void fetchSession().catch(() => undefined),
      Math.max(0, until - Date.now()) + 500,
    );
  }
  return s;
}

async function errorOf(r: Response, fallback: string): Promise<AuthError> {
  let message = fallback;
  let retry: number | null = null;
  try {
    const b = (await r.json()) as { error?: unknown; retryAfterS?: unknown };
    if (typeof b.error === 'string') message = b.error;
    if (typeof b.retryAfterS === 'number') retry = b.retryAfterS;
  } catch {
    // not JSON: keep the fallback
  }
  return new AuthError(message, r.status, retry);
}

async function post(path: string, body?: unknown, method = 'POST'): Promise<Response> {
  return fetch(path, {
    method,
    credentials: 'same-origin',
    headers:
      body === undefined ? CONSOLE_HEADERS : { 'Content-Type': 'application/json', ...CONSOLE_HEADERS },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
}

async function sessionFrom(r: Response): Promise<SessionInfo> {
  return apply(SessionSchema.parse(await r.json()));
}

let checking: Promise<void> | null = null;

/**
 * The console's own server said this page's session is gone: ask it who is signed in (once at a
 * time). Really gone: `authStore.user` becomes null, so every screen shows the sign-in with
 * "Signed out — sign in again" instead of tiles that can no longer be read.
 */
export function checkSession(): Promise<void> {
  if (checking) return checking;
  const had = authStore.getState().mode === 'secured' && authStore.getState().user !== null;
  checking = fetchSession()
    .then((s) => {
      if (had && s.mode === 'secured' && !s.user) sessionExtra.setState({ signedOut: true });
    })
    .catch(() => undefined)
    .finally(() => {
      checking = null;
    });
  return checking;
}
onSessionGone(() => void checkSession());

/** `GET /api/session` into `authStore`. */
export async function fetchSession(): Promise<SessionInfo> {
  const r = await fetch('/api/session', { credentials: 'same-origin', headers: CONSOLE_HEADERS });
  if (!r.ok) throw await errorOf(r, `the gateway answered HTTP ${r.status}`);
  return sessionFrom(r);
}

export async function login(name: string, password: string): Promise<SessionInfo> {
  const r = await post('/api/login', { name, password });
  if (r.status === 401) throw await errorOf(r, 'Wrong name or password.');
  if (r.status === 429) throw await errorOf(r, 'Too many failed logins: wait and try again.');
  if (!r.ok) throw await errorOf(r, `Login failed (HTTP ${r.status}).`);
  return sessionFrom(r);
}

/**
 * What signing out forgets in this browser. The gateway's logout answer says `Clear-Site-Data:
 * "cache", "storage"` (gateway/page-headers.ts), but browsers honour it only in a secure context
 * and only when the answer arrives: the page clears its own storage too (the forms' unsaved
 * drafts of machine settings live in localStorage: src/forms/storage.ts), so nothing of the
 * signed-out person's work is left for the next one on a shared tablet, over plain HTTP on the
 * shop network or with the gateway unreachable. Machine answers are never cached (no-store; the
 * service worker caches only the app shell). The callers then load `/login` afresh, which also
 * drops everything held in memory.
 */
export function forgetLocalData(
  g: { localStorage?: Pick<Storage, 'clear'>; sessionStorage?: Pick<Storage, 'clear'> } = globalThis,
): void {
  for (const read of [() => g.localStorage, () => g.sessionStorage]) {
    try {
      read()?.clear();
    } catch {
      // storage disabled (private mode, policy): nothing kept there either
    }
  }
}

export async function logout(): Promise<void> {
  await post('/api/logout').catch(() => undefined);
  forgetLocalData();
  authStore.setState({ user: null });
  sessionExtra.setState({ elevation: null, idleTimeoutS: null, expired: false });
}

/** A supervisor unlocks this tablet with their PIN for a few minutes. */
export async function elevate(name: string, pin: string): Promise<SessionInfo> {
  const r = await post('/api/elevate', { name, pin });
  if (r.status === 401) throw await errorOf(r, 'Wrong supervisor name or PIN.');
  if (r.status === 429) throw await errorOf(r, 'Too many wrong PINs: wait and try again.');
  if (!r.ok) throw await errorOf(r, `Unlock failed (HTTP ${r.status}).`);
  return sessionFrom(r);
}

/** Back to the operator at once ("Lock"). */
export async function endElevation(): Promise<SessionInfo> {
  const r = await post('/api/elevate', undefined, 'DELETE');
  if (!r.ok && r.status !== 401) throw await errorOf(r, `HTTP ${r.status}`);
  return sessionFrom(r);
}

/**
 * The idle timeout counts from the last thing a person did, not from the last poll: report
 * taps and keys to the gateway, at most once a minute. Returns a function that stops it.
 */
export function trackActivity(
  target: Pick<Window, 'addEventListener' | 'removeEventListener'> = window,
  everyMs = 60_000,
): () => void {
  let last = 0;
  const onInput = (): void => {
    const now = Date.now();
    if (now - last < everyMs || authStore.getState().mode !== 'secured' || !authStore.getState().user) return;
    last = now;
    void post('/api/session/activity')
      .then(async (r) => {
        if (r.status === 401) await sessionFrom(r);
      })
      .catch(() => undefined);
  };
  target.addEventListener('pointerdown', onInput, { passive: true });
  target.addEventListener('keydown', onInput);
  return () => {
    target.removeEventListener('pointerdown', onInput);
    target.removeEventListener('keydown', onInput);
  };
}

/** Audit page helpers: the same filters for the table and the CSV link. */
export interface AuditFilters {
  machine?: string;
  user?: string;
  result?: string;
  /** ISO or datetime-local value */
  from?: string;
  to?: string;
}

export function auditQuery(f: AuditFilters, paging?: { offset: number; limit: number }): string {
  const q = new URLSearchParams();
  for (const k of ['machine', 'user', 'result'] as const) {
    const v = f[k]?.trim();
    if (v) q.set(k, v);
  }
  for (const k of ['from', 'to'] as const) {
    const v = f[k];
    if (!v) continue;
    const t = new Date(v).getTime();
    if (Number.isFinite(t)) q.set(k, new Date(t).toISOString());
  }
  if (paging) {
    q.set('offset', String(paging.offset));
    q.set('limit', String(paging.limit));
  }
  const s = q.toString();
  return s ? `?${s}` : '';
}
