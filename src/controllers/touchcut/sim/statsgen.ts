/**
 * Deterministic production statistics for the simulated TouchCut: the same day always gives the
 * same numbers, so any date range has consistent totals (a range is the sum of its days).
 *
 * The field names follow the manual's `rest/v1/stats` template. The wrapper that holds a day's
 * sessions, programs and errors is unnamed in the manual (a page break); the simulator calls it
 * `days: [{ date, sessions, programs, errors }]` (the client accepts any name).
 *
 * Internally everything is metric (mm, seconds); `scaleLength` converts for `units=imperial`.
 * Interpretation used here (the manual gives no definitions): activeTime = the whole session,
 * split exactly into productive + unproductive + error + idle; toolOnTime ⊂ productive;
 * xyMovingTime ⊂ productive + unproductive.
 */

export interface DayCarriage {
  carriage: number;
  time: number;
  distance: number;
  starts: number;
  errors: number;
}

export interface DayToolTotals {
  tool: number;
  name: string;
  time: number;
  distance: number;
  starts: number;
  errors: number;
  carriages: DayCarriage[];
}

export interface DaySession {
  user: string;
  startTime: string;
  finishTime: string;
  activeTime: number;
  errorTime: number;
  idleTime: number;
  xyMovingTime: number;
  productiveTime: number;
  unproductiveTime: number;
  toolOnTime: number;
  toolTotals: DayToolTotals[];
}

export interface DayConsumable {
  date: string;
  toolName: string;
  material: string;
  thickness: number;
  process: string;
  consType: string;
  consID: string;
  pierces: number;
  distance: number;
  time: number;
}

export interface Day {
  date: string;
  sessions: DaySession[];
  programs: Array<{ startTime: string; name: string }>;
  errors: Array<{ errorTime: string; error: string }>;
  consumables: DayConsumable[];
}

function hash(s: string): number {
  let h = 2166136261;
  for (let i = 0; i < s.length; i++) {
    h ^= s.charCodeAt(i);
    h = Math.imul(h, 16777619);
  }
  return h >>> 0;
}

/** mulberry32 */
function rng(seed: number): () => number {
  let a = seed;
  return () => {
    a = (a + 0x6d2b79f5) | 0;
    let t = Math.imul(a ^ (a >>> 15), 1 | a);
    t = (t + Math.imul(t ^ (t >>> 7), 61 | t)) ^ t;
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

export const SIM_TOOLS = [
  { tool: 1, name: 'Plasma' },
  { tool: 2, name: 'Marker' },
] as const;

export const PROGRAM_NAMES = ['BRACKET-10MM', 'FLANGE-6MM', 'GUSSET-12MM', 'BASEPLATE-20MM', 'RIB-8MM'];
const ERRORS = ['Torch collision detected', 'Arc lost', 'Low gas pressure', 'Transfer failed'];
const JOBS = [
  { material: 'MS', thickness: 10, process: 'MS 10mm 130A O2/Air', consSet: 'H130' },
  { material: 'MS', thickness: 6, process: 'MS 6mm 80A O2/Air', consSet: 'H080' },
  { material: 'SS', thickness: 12, process: 'SS 12mm 130A H35/N2', consSet: 'S130' },
];
export const CONS_TYPES = ['Electrode', 'Nozzle', 'Swirl Ring', 'Shield'];

const r1 = (x: number) => Math.round(x * 10) / 10;

function at(date: string, seconds: number): string {
  const h = Math.floor(seconds / 3600);
  const m = Math.floor((seconds % 3600) / 60);
  const s = Math.floor(seconds % 60);
  return `${date}T${String(h).padStart(2, '0')}:${String(m).padStart(2, '0')}:${String(s).padStart(2, '0')}`;
}

/** One simulated day of production (metric). */
export function simDay(date: string): Day {
  const rand = rng(hash(`touchcut:${date}`));
  const dow = new Date(`${date}T12:00:00Z`).getUTCDay();
  const weekend = dow === 0 || dow === 6;
  const shifts: Array<{ user: string; start: number }> = weekend
    ? rand() < 0.4
      ? [{ user: 'Operator', start: 7 * 3600 }]
      : []
    : [
        { user: 'Operator', start: 6 * 3600 },
        { user: rand() < 0.5 ? 'Sam' : 'Alex', start: 14 * 3600 },
      ];
  const day: Day = { date, sessions: [], programs: [], errors: [], consumables: [] };
  for (const shift of shifts) {
    const active = Math.round((weekend ? 3 : 7 + rand()) * 3600);
    const productive = Math.round(active * (0.35 + rand() * 0.25));
    const errorCount = rand() < 0.5 ? 0 : 1 + Math.floor(rand() * 2);
    const errorTime = errorCount * Math.round(300 + rand() * 900);
    const unproductive = Math.round(active * (0.1 + rand() * 0.1));
    const idle = active - productive - unproductive - errorTime;
    const toolOn = Math.round(productive * 0.85);
    const xyMoving = Math.round(productive + unproductive * 0.6);
    const job = JOBS[Math.floor(rand() * JOBS.length)] ?? JOBS[0]!;
    const feedMmPerS = 2400 / 60 + rand() * 10;
    const distance = r1(toolOn * feedMmPerS);
    const pierces = Math.round(toolOn / (25 + rand() * 20));
    const markerTime = Math.round(productive * 0.05 * rand());
    const markerDist = r1(markerTime * 100);
    const markerStarts = markerTime > 0 ? Math.round(markerTime / 10) : 0;
    const toolTotals: DayToolTotals[] = [
      {
        tool: 1,
        name: 'Plasma',
        time: toolOn,
        distance,
        starts: pierces,
        errors: errorCount,
        carriages: [{ carriage: 1, time: toolOn, distance, starts: pierces, errors: errorCount }],
      },
      {
        tool: 2,
        name: 'Marker',
        time: markerTime,
        distance: markerDist,
        starts: markerStarts,
        errors: 0,
        carriages: [{ carriage: 1, time: markerTime, distance: markerDist, starts: markerStarts, errors: 0 }],
      },
    ];
    day.sessions.push({
      user: shift.user,
      startTime: at(date, shift.start),
      finishTime: at(date, shift.start + active),
      activeTime: active,
      errorTime,
      idleTime: idle,
      xyMovingTime: xyMoving,
      productiveTime: productive,
      unproductiveTime: unproductive,
      toolOnTime: toolOn,
      toolTotals,
    });
    const runs = 3 + Math.floor(rand() * 6);
    for (let i = 0; i < runs; i++) {
      day.programs.push({
        startTime: at(date, shift.start + Math.floor(((i + rand() * 0.5) * active) / runs)),
        name: `${PROGRAM_NAMES[Math.floor(rand() * PROGRAM_NAMES.length)] ?? 'PART'}.nc`,
      });
    }
    for (let i = 0; i < errorCount; i++) {
      day.errors.push({
        errorTime: at(date, shift.start + Math.floor(rand() * active)),
        error: ERRORS[Math.floor(rand() * ERRORS.length)] ?? 'Error',
      });
    }
    // Every plasma consumable of the set sees the whole plasma cut of the session.
    for (const consType of CONS_TYPES) {
      day.consumables.push({
        date: at(date, shift.start),
        toolName: 'Plasma',
        material: job.material,
        thickness: job.thickness,
        process: job.process,
        consType,
        consID: `${job.consSet}-${consType.slice(0, 2).toUpperCase()}`,
        pierces,
        distance,
        time: toolOn,
      });
    }
  }
  return day;
}

export function isoDate(ms: number): string {
  return new Date(ms).toISOString().slice(0, 10);
}

export function addDays(date: string, n: number): string {
  return isoDate(Date.parse(`${date}T00:00:00Z`) + n * 86_400_000);
}

/** Days from `start` (inclusive) to `endBefore` (exclusive). */
export function daysIn(start: string, endBefore: string): string[] {
  const out: string[] = [];
  for (let d = start; d < endBefore && out.length < 4000; d = addDays(d, 1)) out.push(d);
  return out;
}
