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

/** The principal commands are sent as. In open mode everyone is a supervisor. */
export function currentPrincipal(): Principal {
  const s = authStore.getState();
  if (s.mode === 'open' || s.mode === 'unknown') return { name: 'anyone (open mode)', role: 'supervisor' };
  if (!s.user) return { name: 'nobody', role: 'viewer' };
  return { name: s.user.name, role: s.user.role };
}
