import type { SessionContext } from '../fleet/contract';
import { useNow, useSnapshot } from '../fleet/react';
import { formatAge, formatDateTime } from '../ui';
import { STALE_MS } from './status';

/**
 * Data younger than this reads "live": a machine answering every second or two keeps one steady
 * label instead of a text that changes (and lays the page out) every second (issue 16).
 */
export const LIVE_MS = 3000;

/**
 * How old a machine's data is ("live", "updated 5 s ago", "stale · 12 s ago"): the one part of a
 * tile or a machine page that follows the shared clock's tick, so only it re-renders then.
 */
export function Age({ at, testId = 'data-age' }: { at: number | null; testId?: string }) {
  const now = useNow(1000);
  const stale = at === null || now - at > STALE_MS;
  const live = at !== null && now - at < LIVE_MS;
  return (
    <span
      className={stale ? 'age stale' : 'age'}
      data-testid={testId}
      data-stale={stale}
      title={at === null ? undefined : formatDateTime(at)}
      // When the data arrived (page clock): the 100-machine bench times data to DOM with it.
      data-updated-at={at ?? undefined}
    >
      {at === null
        ? 'no data yet'
        : stale
          ? `stale · ${formatAge(at, now)}`
          : live
            ? 'live'
            : `updated ${formatAge(at, now)}`}
    </span>
  );
}

/**
 * A machine's data age, reading the machine's `updatedAt` itself: a new answer that changes
 * nothing else re-renders this line only, not the tile or page around it.
 */
export function MachineAge({ rt, testId }: { rt: Pick<SessionContext, 'snapshot'>; testId?: string }) {
  const at = useSnapshot(rt, (x) => x.updatedAt);
  return <Age at={at} {...(testId ? { testId } : {})} />;
}

/** " — next try in 3 s." while a retry is due (counts down on the shared clock), else nothing. */
export function RetryIn({ at }: { at: number | null }) {
  const now = useNow(1000);
  if (at === null || at <= now) return null;
  return <> — next try in {Math.ceil((at - now) / 1000)} s.</>;
}
