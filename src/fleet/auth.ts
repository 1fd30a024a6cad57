import { createStore } from 'zustand/vanilla';
import type { Principal } from './commands';
import type { Role } from './types';

/**
 * Who is using the console, as the gateway told us (`GET /api/session`). The gateway enforces
 * roles on every request; this copy only decides what the UI hides, disables and explains.
 */
export interface AuthState {
  /** open: no users file, anyone on the network can control the machines. */
  mode: 'open' | 'secured' | 'unknown';
  /** Open mode served to the network on purpose (SHOPDECK_OPEN=1). */
  openOnNetwork?: boolean;
  user: { name: string; role: Role; machines: string[] | null } | null;
}

export const authStore = createStore<AuthState>(() => ({ mode: 'unknown', user: null }));

/**
 * The console's own server said this page's session is gone (its own 401, marked
 * `X-Shopdeck-Gateway`, or the read socket closed 4401): never a controller's 401, which is that
 * machine's answer only. The listener (src/app/auth/api.ts) asks the server who is signed in.
 */
const sessionGoneListeners = new Set<() => void>();
export function onSessionGone(fn: () => void): () => void {
  sessionGoneListeners.add(fn);
  return () => sessionGoneListeners.delete(fn);
}
export function sessionGone(): void {
  for (const fn of sessionGoneListeners) fn();
}

/** The principal commands are sent as. In open mode everyone is a supervisor. */
export function currentPrincipal(): Principal {
  const s = authStore.getState();
  if (s.mode === 'open' || s.mode === 'unknown') return { name: 'anyone (open mode)', role: 'supervisor' };
  if (!s.user) return { name: 'nobody', role: 'viewer' };
  return { name: s.user.name, role: s.user.role };
}
