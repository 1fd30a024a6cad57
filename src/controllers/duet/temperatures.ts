import type { JsonRecord, TemperatureDecl, TemperatureReading } from '../../fleet/contract';
import { isObject, type Json } from './patch';

/**
 * The heaters' temperatures the gateway keeps for the Overview's chart (gateway/temperatures.ts),
 * read from the raw object model (untrusted: nothing here believes a type; the gateway bounds
 * what comes out). Named as the page names them (snapshot.ts `heaterName`), keyed by heater index
 * (the page's chart history is too: state.ts).
 */

/** Heaters looked at (RepRapFirmware has at most 32 on a Duet 3); the gateway keeps fewer. */
const MOST_HEATERS = 64;

function numbers(v: Json | undefined): number[] {
  return Array.isArray(v) ? v.filter((x): x is number => typeof x === 'number') : [];
}

function nameOf(model: JsonRecord, index: number): string {
  const heat = isObject(model['heat']) ? model['heat'] : {};
  const beds = numbers(heat['bedHeaters']);
  if (beds.includes(index)) return beds.filter((h) => h >= 0).length > 1 ? `Bed ${index}` : 'Bed';
  if (numbers(heat['chamberHeaters']).includes(index)) return 'Chamber';
  const tools = Array.isArray(model['tools']) ? model['tools'].slice(0, MOST_HEATERS) : [];
  for (const t of tools) {
    if (!isObject(t) || !numbers(t['heaters']).includes(index)) continue;
    const num = typeof t['number'] === 'number' ? t['number'] : null;
    const name = typeof t['name'] === 'string' ? t['name'] : '';
    if (num === null) continue;
    return name ? `${name} (T${num})` : `Tool ${num}`;
  }
  return `Heater ${index}`;
}

/** Every configured heater of a model: its current reading (-273.15, "no sensor", is null). */
export function duetTemperatures(model: JsonRecord): TemperatureReading[] | null {
  const heat = model['heat'];
  if (!isObject(heat) || !Array.isArray(heat['heaters'])) return null;
  const out: TemperatureReading[] = [];
  heat['heaters'].slice(0, MOST_HEATERS).forEach((h, i) => {
    if (!isObject(h)) return;
    const c = h['current'];
    out.push({
      key: String(i),
      name: nameOf(model, i),
      value: typeof c === 'number' && c > -273 ? c : null,
    });
  });
  return out;
}

function parse(body: string): JsonRecord | null {
  try {
    const v: unknown = JSON.parse(body);
    return isObject(v) ? v : null;
  } catch {
    return null;
  }
}

/**
 * DSF: the shared `WS /machine`'s merged model (the gateway's own, read every second), and the
 * watch's `GET /machine/model`. A standalone board: the watch's `rr_model` poll (`{result}`).
 */
export const duetTemperatureDecl: TemperatureDecl = {
  fromModel: duetTemperatures,
  fromPoll(path, status, body) {
    if (status < 200 || status > 299) return null;
    const obj = parse(body);
    if (!obj) return null;
    if (path.startsWith('/rr_model')) {
      const result = obj['result'];
      return isObject(result) ? duetTemperatures(result) : null;
    }
    return duetTemperatures(obj);
  },
};
