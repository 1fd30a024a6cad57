import type { TemperatureDecl, TemperatureReading } from '../../fleet/contract';

/**
 * The temperatures the gateway keeps for the live chart (gateway/temperatures.ts), read from a
 * status tick of the watched `/websocket/everything` (untrusted: nothing here believes a type; the
 * gateway bounds what comes out). Keyed as the page's chart keys its series (status.ts `derive`:
 * "group · name"), and only what the chart calls a temperature (LiveChart.tsx `kindOf`: a name
 * with "temperat", not a power or a position).
 */

/** Entries looked at in one tick (the gateway keeps fewer sensors). */
const MOST_ENTRIES = 256;

function isRecord(v: unknown): v is Record<string, unknown> {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

function isTemperatureGroup(group: string): boolean {
  return /temperat/i.test(group) && !/power|position/i.test(group);
}

/** The temperature entries of one tick's values: module API `{module: {group: {name: v}}}` or flat `{group: {name: v}}`. */
export function pruntTemperatures(frame: string): TemperatureReading[] | null {
  let json: unknown;
  try {
    json = JSON.parse(frame);
  } catch {
    return null;
  }
  if (!isRecord(json)) return null;
  const groups: Array<[string, unknown]> = [];
  if (isRecord(json['Status_Values'])) {
    for (const mod of Object.values(json['Status_Values']))
      if (isRecord(mod)) groups.push(...Object.entries(mod));
  } else if (isRecord(json['Status'])) {
    groups.push(...Object.entries(json['Status']));
  } else return null;
  const out: TemperatureReading[] = [];
  let seen = 0;
  for (const [group, entries] of groups) {
    if (!isRecord(entries) || !isTemperatureGroup(group)) continue;
    for (const [name, v] of Object.entries(entries)) {
      if (++seen > MOST_ENTRIES) return out;
      out.push({ key: `${group} · ${name}`, name, value: typeof v === 'number' ? v : null });
    }
  }
  return out;
}

export const pruntTemperatureDecl: TemperatureDecl = { fromFrame: pruntTemperatures };
