import { useEffect, useState } from 'react';
import type { z } from 'zod/mini';
import { request } from './api';

export interface Query<T> {
  /** The last good answer (kept while a newer request fails or is under way). */
  data: T | null;
  error: string | null;
  status: number;
  loading: boolean;
}

/** GETs `url` (null: nothing to ask) again whenever it or `tick` changes. */
export function useQuery<T>(
  schema: z.ZodMiniType<T>,
  url: string | null,
  what: string,
  tick: number,
): Query<T> {
  const [q, setQ] = useState<Query<T>>({ data: null, error: null, status: 0, loading: url !== null });
  useEffect(() => {
    if (url === null) return;
    const ctl = new AbortController();
    setQ((s) => ({ ...s, loading: true }));
    request(schema, url, what, { signal: ctl.signal })
      .then((r) => {
        if (ctl.signal.aborted) return;
        setQ((s) =>
          r.ok
            ? { data: r.data, error: null, status: 200, loading: false }
            : { data: s.data, error: r.error, status: r.status, loading: false },
        );
      })
      .catch(() => {
        // aborted: a newer request replaced this one
      });
    return () => ctl.abort();
  }, [schema, url, what, tick]);
  return q;
}
