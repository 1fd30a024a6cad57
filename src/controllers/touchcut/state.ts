import type { StoreApi } from 'zustand/vanilla';
import { createSharedStore } from '../../fleet/kernel';
import { UNITS_CHOICES, type MachineInfoWire, type Status, type UnitsChoice } from './wire';

/** The TouchCut session's own state (beyond the machine snapshot), and the units choice. */

export interface TouchcutAuthState {
  /** 'key': requests rely on the gateway's API key; 'user': a TouchCut user JWT is in memory. */
  mode: 'key' | 'user';
  user: string | null;
  /** JWT expiry (ms since epoch) if the token says so (display only). */
  expiresAt: number | null;
  /** Why a login is needed, in words. */
  reason: string | null;
}

export interface TouchcutState {
  info: MachineInfoWire | null;
  status: Status | null;
  statusAt: number | null;
  auth: TouchcutAuthState;
  /** A passing condition shown as a notice, not an error (TouchCut "application not ready"). */
  notice: string | null;
}

export const KEY_AUTH: TouchcutAuthState = { mode: 'key', user: null, expiresAt: null, reason: null };

export function createTouchcutStore(): StoreApi<TouchcutState> {
  return createSharedStore<TouchcutState>(() => ({
    info: null,
    status: null,
    statusAt: null,
    auth: KEY_AUTH,
    notice: null,
  }));
}

/** Units are a per-user choice of the console user (kept in this browser; not a secret). */
const UNITS_KEY = 'shopdeck.touchcut.units';

function loadUnits(): UnitsChoice {
  try {
    const v = globalThis.localStorage?.getItem(UNITS_KEY);
    return UNITS_CHOICES.includes(v as UnitsChoice) ? (v as UnitsChoice) : 'default';
  } catch {
    return 'default';
  }
}

export const touchcutUnits: StoreApi<{ units: UnitsChoice }> = createSharedStore(() => ({
  units: loadUnits(),
}));

export function setTouchcutUnits(units: UnitsChoice): void {
  touchcutUnits.setState({ units });
  try {
    globalThis.localStorage?.setItem(UNITS_KEY, units);
  } catch {
    /* storage unavailable: the choice lasts for this page */
  }
}

/** Reads `exp` of a JWT for display. The token is untrusted: any failure gives null. */
export function jwtExpiry(token: string): number | null {
  try {
    const part = token.split('.')[1];
    if (!part) return null;
    const json = atob(part.replace(/-/g, '+').replace(/_/g, '/') + '==='.slice((part.length + 3) % 4));
    const exp = (JSON.parse(json) as { exp?: unknown }).exp;
    return typeof exp === 'number' && Number.isFinite(exp) ? exp * 1000 : null;
  } catch {
    return null;
  }
}
