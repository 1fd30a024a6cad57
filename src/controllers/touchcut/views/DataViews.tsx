import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { useNow } from '../../../fleet/react';
import { Button, EmptyState, Field, Notice, Panel, formatAge } from '../../../ui';
import { useOpenData } from '../queries';
import type { TouchcutSession } from '../session';
import { localDate, presetRange } from '../stats';
import { DataTree } from './common';

const SUBJECT_TO_CHANGE = (
  <p className="ui-muted small">
    The manual marks this part of the TouchCut API “subject to change”: it is shown as the machine sends it.
  </p>
);

/** `rest/v1/programs` with `offset`/`limit` pages; refreshes ask only for changed data. */
export function ProgramsView({ session }: TabProps<TouchcutSession>) {
  const s = useOpenData(session.programs);
  const now = useNow(1000);
  const total = s.data && !Array.isArray(s.data) && typeof s.data.total === 'number' ? s.data.total : null;
  return (
    <div className="tc-stack" data-testid="touchcut-programs">
      <div className="ui-row">
        <Button disabled={s.offset === 0} onClick={() => session.programs.page(s.offset - s.limit, s.limit)}>
          <span aria-hidden="true">←</span> Previous
        </Button>
        <span>
          {total === 0
            ? 'none'
            : `${s.offset + 1}–${total !== null ? Math.min(total, s.offset + s.limit) : s.offset + s.limit}`}
          {total !== null ? ` of ${total}` : ''}
        </span>
        <Button
          disabled={total !== null && s.offset + s.limit >= total}
          onClick={() => session.programs.page(s.offset + s.limit, s.limit)}
        >
          Next <span aria-hidden="true">→</span>
        </Button>
        <label className="tc-units">
          <span className="ui-muted small">Per page</span>
          <select
            className="ui-input"
            value={s.limit}
            onChange={(e) => session.programs.page(0, Number(e.target.value))}
          >
            {[10, 25, 50, 100].map((n) => (
              <option key={n}>{n}</option>
            ))}
          </select>
        </label>
        <Button onClick={() => session.programs.reload()}>Reload</Button>
        <span className="ui-muted small">
          {s.at ? `updated ${formatAge(s.at, now)}` : s.loading ? 'loading…' : ''}
        </span>
      </div>
      {s.error && <Notice tone="warn">{s.error}</Notice>}
      {SUBJECT_TO_CHANGE}
      <Panel title="Programs">
        {s.data ? (
          <DataTree value={s.data} />
        ) : (
          <EmptyState>{s.loading ? 'Loading…' : 'Nothing yet.'}</EmptyState>
        )}
      </Panel>
    </div>
  );
}

/** `rest/v1/unloader`: pallet stations, and the unloaded-parts history for a date range. */
export function UnloaderView({ session }: TabProps<TouchcutSession>) {
  const s = useOpenData(session.unloader);
  const now = useNow(1000);
  const today = localDate(new Date());
  const [range, setRange] = useState(() => s.history ?? presetRange('today', today));
  const data = s.data && !Array.isArray(s.data) ? (s.data as Record<string, unknown>) : null;
  const rest = data
    ? Object.fromEntries(Object.entries(data).filter(([k]) => k !== 'history' && k !== 'units'))
    : s.data;
  return (
    <div className="tc-stack" data-testid="touchcut-unloader">
      {s.error && <Notice tone="warn">{s.error}</Notice>}
      {SUBJECT_TO_CHANGE}
      <Panel
        title="Part unloader"
        actions={<span className="ui-muted small">{s.at ? `updated ${formatAge(s.at, now)}` : ''}</span>}
      >
        {s.data ? (
          <DataTree value={rest} />
        ) : (
          <EmptyState>{s.loading ? 'Loading…' : 'Nothing yet.'}</EmptyState>
        )}
      </Panel>
      <Panel title="History">
        <form
          className="ui-row"
          onSubmit={(e) => {
            e.preventDefault();
            if (range.startDate < range.endBeforeDate) session.unloader.setHistory(range);
          }}
        >
          <Field label="From">
            {(id) => (
              <input
                id={id}
                type="date"
                className="ui-input"
                value={range.startDate}
                onChange={(e) => setRange({ ...range, startDate: e.target.value })}
              />
            )}
          </Field>
          <Field label="Until (not included)">
            {(id) => (
              <input
                id={id}
                type="date"
                className="ui-input"
                value={range.endBeforeDate}
                onChange={(e) => setRange({ ...range, endBeforeDate: e.target.value })}
              />
            )}
          </Field>
          <Button type="submit" variant="primary" disabled={range.startDate >= range.endBeforeDate}>
            Show history
          </Button>
          {s.history && <Button onClick={() => session.unloader.setHistory(null)}>Hide history</Button>}
        </form>
        {s.history && data && <DataTree value={data.history ?? '(no history in the answer)'} />}
      </Panel>
    </div>
  );
}
