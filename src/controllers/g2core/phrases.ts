/**
 * g2core's words as people at the machine read them, with the firmware's own token kept for a
 * technician (shown small, never alone). The overrides (g2core wiki, "Feedrate override" and
 * config_app.cpp): `mfo` the feed rate factor, `mto` the traverse (rapid) factor, `sso` the
 * spindle speed factor, each 0.05 – 2.0 (1 = 100 %); `mfoe`, `mtoe`, `ssoe` turn each one on (1)
 * or off (0). Off, the factor is kept but the machine runs at 100 %.
 */
export interface OverridePhrase {
  /** What it is called on the page. */
  what: string;
  /** The factor's token and its on/off token (the firmware's words, for the subtitle). */
  factor: 'mfo' | 'mto' | 'sso';
  enable: 'mfoe' | 'mtoe' | 'ssoe';
  /** The settings row that turns it on (settings-meta.ts). */
  setting: string;
}

export const OVERRIDE_PHRASES: Record<'mfo' | 'mto' | 'sso', OverridePhrase> = {
  mfo: { what: 'Feed override', factor: 'mfo', enable: 'mfoe', setting: 'Feed override enable' },
  mto: { what: 'Rapid override', factor: 'mto', enable: 'mtoe', setting: 'Traverse override enable' },
  sso: { what: 'Spindle override', factor: 'sso', enable: 'ssoe', setting: 'Spindle override enable' },
};

/** A factor (1 = 100 %) as people read it: "100 %", "85 %". */
export function percent(factor: number): string {
  return `${Math.round(factor * 100)} %`;
}

/**
 * An override's state in one line: "Feed override: 85 %", or when it is turned off in the
 * machine's settings "Feed override: off — the machine runs at 100 % (the 85 % set is kept)".
 */
export function overrideLine(p: OverridePhrase, factor: number, on: boolean | null): string {
  if (on === false)
    return `${p.what}: off — the machine runs at 100 %${Math.round(factor * 100) !== 100 ? ` (the ${percent(factor)} set is kept)` : ''}`;
  return `${p.what}: ${percent(factor)}`;
}
