import { Notice } from '../../ui';
import type { Query } from './useQuery';

/** A failed request in words; what was shown before stays below it. */
export function QueryProblem(props: { q: Query<unknown>; what: string }) {
  const { q } = props;
  if (q.error === null) return q.loading && q.data === null ? <p className="ui-muted">Loading…</p> : null;
  return (
    <Notice tone={q.status === 403 || q.status === 401 ? 'warn' : 'bad'} title={`Cannot load ${props.what}`}>
      {q.error}
      {q.data !== null && ' What is shown is from the last answer.'}
    </Notice>
  );
}
