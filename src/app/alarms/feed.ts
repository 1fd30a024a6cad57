import { z } from 'zod/mini';
import { createStore } from 'zustand/vanilla';
import { alarmRecordSchema, type AlarmRecord } from '../../fleet/alarm-record';
import { authStore, sessionGone } from '../../fleet/auth';
import { allRuntimes } from '../../fleet/fleet';
import { CONSOLE_HEADERS } from '../../fleet/origin';

/**
 * The alarm centre as this page knows it: the gateway's list (`GET /api/alarms`, kept by the
 * server whether or not a page is open), asked for every few seconds while signed in (`since`:
 * an unchanged list is not sent again). Every byte of it is checked; a bad answer is an error on
 * screen, and the last good list stays.
 */

export type { AlarmRecord };

const answerSchema = z.union([
  z.object({ version: z.number(), unchanged: z.literal(true) }),
  z.object({ version: z.number(), alarms: z.array(alarmRecordSchema).check(z.maxLength(5000)) }),
]);

export interface AlarmFeedState {
  /** null until the first answer. */
  records: AlarmRecord[] | null;
  version: number | null;
  /** The last failure in words (the list shown is the last good one). */
  error: string | null;
  /** When the list was last confirmed (ms). */
  checkedAt: number | null;
}

export const alarmFeed = createStore<AlarmFeedState>(() => ({
  records: null,
  version: null,
  error: null,
  checkedAt: null,
}));

export const POLL_MS = 3000;
export const HIDDEN_POLL_MS = 15_000;

/** Records first seen by this page after its first answer (notifications). */
type NewListener = (r: AlarmRecord) => void;
const newListeners = new Set<NewListener>();
export function onNewAlarm(fn: NewListener): () => void {
  newListeners.add(fn);
  return () => newListeners.delete(fn);
}

let timer: ReturnType<typeof setTimeout> | null = null;
let inFlight: AbortController | null = null;
let started = false;

function signedIn(): boolean {
  const a = authStore.getState();
  return a.mode === 'open' || (a.mode === 'secured' && a.user !== null);
}

/** One read of the list now. */
export async function refreshAlarms(): Promise<void> {
  if (!signedIn()) return;
  inFlight?.abort();
  const ctl = new AbortController();
  inFlight = ctl;
  const before = alarmFeed.getState();
  const since = before.version === null ? '' : `&since=${before.version}`;
  try {
    const r = await fetch(`/api/alarms?limit=500${since}`, {
      credentials: 'same-origin',
      headers: CONSOLE_HEADERS,
      signal: ctl.signal,
    });
    if (!r.ok) {
      // The console's own 401: this page's session is gone (the sign-in is shown).
      if (r.status === 401) sessionGone();
      alarmFeed.setState({ error: `The alarm list could not be read (HTTP ${r.status}).` });
      return;
    }
    const parsed = answerSchema.safeParse(await r.json());
    if (!parsed.success) {
      alarmFeed.setState({ error: 'The alarm list the console sent is malformed.' });
      return;
    }
    const a = parsed.data;
    if ('unchanged' in a) {
      alarmFeed.setState({ error: null, checkedAt: Date.now() });
      return;
    }
    const known = before.records ? new Set(before.records.map((x) => x.id)) : null;
    const prevAck = new Map((before.records ?? []).map((x) => [x.id, x.ackAt]));
    alarmFeed.setState({ records: a.alarms, version: a.version, error: null, checkedAt: Date.now() });
    for (const rec of a.alarms) {
      if (known && !known.has(rec.id)) for (const fn of newListeners) fn(rec);
      // Acknowledged elsewhere while this page watched: the same alarm on this page's own view
      // of the machine is acknowledged too (an xTool flame has no acknowledgement of its own).
      if (prevAck.get(rec.id) === null && rec.ackAt !== null) acknowledgeLocally(rec.machine, rec.key);
    }
  } catch (e) {
    if (ctl.signal.aborted) return;
    alarmFeed.setState({
      error: `The alarm list could not be read: ${e instanceof Error ? e.message : String(e)}`,
    });
  } finally {
    if (inFlight === ctl) inFlight = null;
  }
}

function acknowledgeLocally(machine: string, key: string): void {
  const rt = allRuntimes().find((r) => r.info.id === machine);
  const local = rt?.snapshot.getState().alarms.find((a) => a.id === key && !a.acknowledged);
  if (local) rt?.session?.acknowledgeAlarm?.(key);
}

function schedule(): void {
  if (timer) clearTimeout(timer);
  const hidden = typeof document !== 'undefined' && document.visibilityState === 'hidden';
  timer = setTimeout(
    () => {
      timer = null;
      void refreshAlarms().finally(schedule);
    },
    hidden ? HIDDEN_POLL_MS : POLL_MS,
  );
}

/** Starts following the list (once per page): now, then every few seconds, at once when shown. */
export function startAlarmFeed(): void {
  if (started) return;
  started = true;
  void refreshAlarms();
  schedule();
  document.addEventListener('visibilitychange', () => {
    if (document.visibilityState === 'visible') void refreshAlarms();
  });
  // A login (or a logout) changes what this person may see.
  authStore.subscribe((s, prev) => {
    if (s.user?.name === prev.user?.name && s.mode === prev.mode) return;
    alarmFeed.setState({ records: null, version: null, error: null });
    void refreshAlarms();
  });
}

export type AckTarget = { id: string } | { machine: string; key: string };

/** How long an acknowledgement of an alarm only this page has seen waits for the console's record. */
export const RECORD_WAIT_MS = 6000;
const RECORD_POLL_MS = 1000;

/** The console's unacknowledged record of a machine's alarm key (the open one first), if listed. */
function listedRecord(machine: string, key: string): AlarmRecord | undefined {
  const mine = (alarmFeed.getState().records ?? []).filter(
    (r) => r.machine === machine && r.key === key && r.ackAt === null,
  );
  return mine.find((r) => r.clearedAt === null) ?? mine.sort((a, b) => b.since - a.since)[0];
}

/**
 * The record of an alarm this page saw before the list had it: the list is read again until the
 * console has recorded it (the gateway's watch sees what this page sees), at most `RECORD_WAIT_MS`.
 */
async function waitForRecord(machine: string, key: string): Promise<AlarmRecord | undefined> {
  const end = Date.now() + RECORD_WAIT_MS;
  for (;;) {
    await refreshAlarms();
    const r = listedRecord(machine, key);
    if (r || Date.now() >= end) return r;
    await new Promise((done) => setTimeout(done, RECORD_POLL_MS));
  }
}

/**
 * Acknowledges an alarm at the gateway (who and when are recorded there) by its record's id,
 * then on this page's own view of the machine. An alarm only this page has seen is acknowledged
 * once the console has recorded it: nothing is acknowledged in advance (the gateway refuses it),
 * so the same alarm is never born acknowledged on the other screens. When the console never
 * records it (its watch does not see the machine), it is acknowledged on this page only, and a
 * record that comes later asks again. Returns an error in words, or null.
 */
export async function acknowledgeAlarm(target: AckTarget): Promise<string | null> {
  let id: string;
  if ('id' in target) id = target.id;
  else {
    const rec = listedRecord(target.machine, target.key) ?? (await waitForRecord(target.machine, target.key));
    if (!rec) {
      acknowledgeLocally(target.machine, target.key);
      return null;
    }
    id = rec.id;
  }
  let r: Response;
  try {
    r = await fetch('/api/alarms/ack', {
      method: 'POST',
      credentials: 'same-origin',
      headers: { ...CONSOLE_HEADERS, 'Content-Type': 'application/json' },
      body: JSON.stringify({ id }),
    });
  } catch (e) {
    return `The acknowledgement did not reach the console: ${e instanceof Error ? e.message : String(e)}`;
  }
  if (!r.ok) {
    let why = `HTTP ${r.status}`;
    try {
      const b = (await r.json()) as { error?: unknown };
      if (typeof b.error === 'string') why = b.error;
    } catch {
      // the status says enough
    }
    return `Not acknowledged: ${why}`;
  }
  const rec = alarmFeed.getState().records?.find((x) => x.id === id);
  if (rec) acknowledgeLocally(rec.machine, rec.key);
  else if ('key' in target) acknowledgeLocally(target.machine, target.key);
  await refreshAlarms();
  return null;
}

/** Stops following (tests). */
export function stopAlarmFeedForTests(): void {
  if (timer) clearTimeout(timer);
  timer = null;
  inFlight?.abort();
  started = false;
  alarmFeed.setState({ records: null, version: null, error: null, checkedAt: null });
}
