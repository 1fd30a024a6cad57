import { useEffect, useState } from 'react';
import { z } from 'zod/mini';
import { apiOrigin, CONSOLE_HEADERS } from './origin';

/**
 * The temperatures the console's server kept of a machine before this page opened
 * (`GET /api/machines/<id>/temperatures`, gateway/temperatures.ts), so a chart starts with the
 * last minutes instead of empty; then the page's own live points follow (`withEarlier`).
 */

export type Point = readonly [number, number];

/** The server's answer (bounded: the gateway keeps at most 24 sensors and 720 samples). */
const answerSchema = z.object({
  now: z.number(),
  windowMs: z.number().check(z.positive(), z.maximum(24 * 3_600_000)),
  sensors: z
    .array(z.object({ key: z.string().check(z.maxLength(200)), name: z.string().check(z.maxLength(200)) }))
    .check(z.maxLength(64)),
  samples: z
    .array(z.array(z.nullable(z.number())).check(z.minLength(1), z.maxLength(65)))
    .check(z.maxLength(5000)),
});

export type EarlierReadings =
  | { state: 'loading' }
  /** `byKey`: each sensor's points in the page's clock. */
  | { state: 'ok'; byKey: ReadonlyMap<string, { name: string; points: Point[] }>; windowMs: number }
  | { state: 'none' }
  | { state: 'error'; message: string };

/**
 * The answer as series in the page's clock: the server's times are moved by the difference of the
 * two clocks (a tablet's clock may differ from the server's): a sample `now - t` old on the
 * server is that old here too.
 */
export function earlierFromAnswer(raw: unknown, pageNow: number): EarlierReadings {
  const p = answerSchema.safeParse(raw);
  if (!p.success) return { state: 'error', message: 'the server’s answer is malformed' };
  const a = p.data;
  const byKey = new Map<string, { name: string; points: Point[] }>();
  a.sensors.forEach((s, i) => {
    const points: Point[] = [];
    for (const sample of a.samples) {
      const t = sample[0];
      const v = sample[i + 1];
      if (typeof t === 'number' && typeof v === 'number') points.push([pageNow - (a.now - t), v]);
    }
    if (points.length) byKey.set(s.key, { name: s.name, points });
  });
  return byKey.size ? { state: 'ok', byKey, windowMs: a.windowMs } : { state: 'none' };
}

export async function readEarlierTemperatures(
  machineId: string,
  pageNow: () => number,
  signal?: AbortSignal,
): Promise<EarlierReadings> {
  try {
    const r = await fetch(`${apiOrigin()}/api/machines/${encodeURIComponent(machineId)}/temperatures`, {
      credentials: 'same-origin',
      headers: CONSOLE_HEADERS,
      signal,
    });
    if (!r.ok) return { state: 'error', message: `HTTP ${r.status}` };
    return earlierFromAnswer(await r.json(), pageNow());
  } catch (e) {
    return { state: 'error', message: e instanceof Error ? e.message : String(e) };
  }
}

/**
 * The earlier points before the live ones: only those older than the first live point (by more
 * than `gapMs`, half a sample), so no moment is drawn twice; with no live point yet, all of them.
 */
export function withEarlier(
  earlier: readonly Point[] | undefined,
  live: readonly Point[],
  gapMs = 500,
): readonly Point[] {
  if (!earlier?.length) return live;
  const first = live[0]?.[0];
  if (first === undefined) return earlier;
  let n = 0;
  while (n < earlier.length && (earlier[n]?.[0] ?? Infinity) < first - gapMs) n++;
  return n === 0 ? live : [...earlier.slice(0, n), ...live];
}

/** What the chart says under it about the earlier readings (null: nothing to say). */
export function earlierNote(e: EarlierReadings): string | null {
  switch (e.state) {
    case 'loading':
      return 'Reading the last minutes from the console’s server…';
    case 'none':
      return 'No earlier readings on the server: the chart starts now.';
    case 'error':
      return `Earlier readings could not be read from the server (${e.message}): the chart starts now.`;
    case 'ok':
      return null;
  }
}

/** The earlier readings of a machine, read once when a chart opens. */
export function useEarlierTemperatures(machineId: string, pageNow: () => number): EarlierReadings {
  const [state, setState] = useState<EarlierReadings>({ state: 'loading' });
  useEffect(() => {
    const ctl = new AbortController();
    setState({ state: 'loading' });
    void readEarlierTemperatures(machineId, pageNow, ctl.signal).then((r) => {
      if (!ctl.signal.aborted) setState(r);
    });
    return () => ctl.abort();
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [machineId]);
  return state;
}
