import type { StoreApi } from 'zustand/vanilla';
import { createSharedStore } from '../../fleet/kernel';
import {
  UNITS_CHOICES,
  type HeldLoginWire,
  type MachineInfoWire,
  type Status,
  type UnitsChoice,
} from './wire';

/** The TouchCut session's own state (beyond the machine snapshot), and the units choice. */

export interface TouchcutAuthState {
  /**
   * 'key': requests rely on the gateway's API key; 'user': the gateway holds a TouchCut user login
   * (JWT) for this machine, shared by every viewer. The browser never holds the token.
   */
  mode: 'key' | 'user';
  user: string | null;
  /** The login's expiry (ms since epoch) as the gateway read it from the JWT (display only). */
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

/** The login state of the gateway's answer (`HeldLogin`, never a token). */
export function authFromHeld(h: HeldLoginWire, fallbackUser: string | null = null): TouchcutAuthState {
  if (!h.loggedIn) return KEY_AUTH;
  return { mode: 'user', user: h.user ?? fallbackUser, expiresAt: h.expiresAt ?? null, reason: null };
}
