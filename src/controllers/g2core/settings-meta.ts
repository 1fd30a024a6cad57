/**
 * Human names and descriptions of the g2core configuration keys, per group kind, for the
 * settings forms. From the g2core configuration pages (wiki "Configuring g2core" / JSON
 * cheat sheet) as best known; the controller stays the authority: a key it refuses as
 * read-only (status 104) is shown read-only from then on, and keys missing here are shown
 * with their raw name. Enum values not listed are shown as "unknown (raw …)".
 */

import { TABLES, type FieldKind, type GroupKind, type KeyMeta } from './settings-tables';

export type { FieldKind, GroupKind, KeyMeta } from './settings-tables';

export function groupKind(group: string): GroupKind {
  if (group === 'sys') return 'sys';
  if (/^[xyzabc]$/.test(group)) return 'axis';
  if (/^\d+$/.test(group)) return 'motor';
  if (/^do\d+$/.test(group)) return 'do';
  if (/^di\d+$/.test(group)) return 'di';
  if (/^he\d+$/.test(group)) return 'heater';
  if (/^g(5[4-9]|92|28|30)$/.test(group)) return 'offset';
  return 'other';
}

export function keyMeta(group: string, key: string): KeyMeta | null {
  return TABLES[groupKind(group)][key] ?? null;
}

const OFFSET_WORDS: Record<string, string> = {
  g54: 'G54 work offset',
  g55: 'G55 work offset',
  g56: 'G56 work offset',
  g57: 'G57 work offset',
  g58: 'G58 work offset',
  g59: 'G59 work offset',
  g92: 'G92 offset (set by G92 in a program)',
  g28: 'G28 position (set by G28.1)',
  g30: 'G30 position (set by G30.1)',
};

/** "X axis", "Motor 2", "Digital input 3", "Heater 1", "G54 work offset", "System". */
export function groupTitle(group: string): string {
  switch (groupKind(group)) {
    case 'sys':
      return 'System';
    case 'axis':
      return `${group.toUpperCase()} axis`;
    case 'motor':
      return `Motor ${group}`;
    case 'do':
      return `Digital output ${group.slice(2)}`;
    case 'di':
      return `Digital input ${group.slice(2)}`;
    case 'heater':
      return `Heater ${group.slice(2)}`;
    case 'offset':
      return OFFSET_WORDS[group] ?? group;
    default:
      return group;
  }
}

export const SECTION_ORDER: { kind: GroupKind; title: string }[] = [
  { kind: 'sys', title: 'System' },
  { kind: 'axis', title: 'Axes' },
  { kind: 'motor', title: 'Motors' },
  { kind: 'di', title: 'Digital inputs' },
  { kind: 'do', title: 'Digital outputs' },
  { kind: 'heater', title: 'Heaters' },
  { kind: 'offset', title: 'Coordinate offsets' },
  { kind: 'other', title: 'Other' },
];

/** Parses what the user typed for a key; returns the JSON value to send or an error sentence. */
export function parseInput(
  meta: KeyMeta | null,
  current: unknown,
  text: string,
): { value: unknown } | { error: string } {
  const kind: FieldKind =
    meta?.kind ??
    (typeof current === 'boolean' ? 'boolean' : typeof current === 'number' ? 'number' : 'text');
  if (kind === 'text') return { value: text };
  if (kind === 'boolean') {
    if (text === 'true' || text === 'false') return { value: text === 'true' };
    return { error: 'Choose true or false' };
  }
  const t = text.trim();
  if (t === '' || !Number.isFinite(Number(t))) return { error: 'Enter a number' };
  const n = Number(t);
  if ((kind === 'integer' || kind === 'enum' || kind === 'flag') && !Number.isInteger(n))
    return { error: 'Enter a whole number' };
  if (meta?.min !== undefined && n < meta.min) return { error: `At least ${meta.min}` };
  if (meta?.max !== undefined && n > meta.max) return { error: `At most ${meta.max}` };
  return { value: n };
}
