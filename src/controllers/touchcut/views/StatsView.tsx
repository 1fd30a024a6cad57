import { useEffect, useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { Button, EmptyState, Field, Notice, Panel } from '../../../ui';
import { useStats, type StatsRequest } from '../queries';
import type { TouchcutSession } from '../session';
import { localDate, presetRange, RANGE_PRESETS, type RangePreset } from '../stats';
import { UnitsPicker } from './common';
import { StatsBody } from './StatsBody';

/**
 * Production statistics (`rest/v1/stats`): pick a range (start date, end before date — the
 * machine clips it to its logging range), condensed or not; every table exports CSV.
 */
export function StatsView({ session }: TabProps<TouchcutSession>) {
  const { data, loading, error, request } = useStats(session.stats);
  const today = localDate(new Date());
  const [form, setForm] = useState<StatsRequest>(
    () => request ?? { ...presetRange('yesterday', today), condensed: false },
  );
  const load = (r: StatsRequest) => {
    setForm(r);
    void session.stats.load(r);
  };
  // First visit: load yesterday straight away (what a supervisor looks at every morning). The
  // units are part of the read's key: a units change reads again by itself.
  const [first] = useState(form);
  useEffect(() => {
    if (!session.stats.store.getState().request) void session.stats.load(first);
  }, [session, first]);
  const preset = (p: RangePreset) => load({ ...presetRange(p, today), condensed: form.condensed });
  const valid = form.startDate !== '' && form.endBeforeDate !== '' && form.startDate < form.endBeforeDate;

  return (
    <div className="tc-stack" data-testid="touchcut-stats">
      <Panel title="Range">
        <div className="ui-row" role="group" aria-label="Range presets">
          {RANGE_PRESETS.map((p) => {
            const r = presetRange(p.id, today);
            const active = r.startDate === form.startDate && r.endBeforeDate === form.endBeforeDate;
            return (
              <Button
                key={p.id}
                variant={active ? 'primary' : 'secondary'}
                aria-pressed={active}
                onClick={() => preset(p.id)}
                data-testid={`stats-preset-${p.id}`}
              >
                {p.label}
              </Button>
            );
          })}
        </div>
        <form
          className="ui-row tc-range"
          onSubmit={(e) => {
            e.preventDefault();
            if (valid) load(form);
          }}
        >
          <Field label="From (first day)">
            {(id) => (
              <input
                id={id}
                type="date"
                className="ui-input"
                value={form.startDate}
                onChange={(e) => setForm({ ...form, startDate: e.target.value })}
                data-testid="stats-start"
              />
            )}
          </Field>
          <Field label="Until (day not included)">
            {(id) => (
              <input
                id={id}
                type="date"
                className="ui-input"
                value={form.endBeforeDate}
                onChange={(e) => setForm({ ...form, endBeforeDate: e.target.value })}
                data-testid="stats-end"
              />
            )}
          </Field>
          <label className="tc-check">
            <input
              type="checkbox"
              checked={form.condensed}
              onChange={(e) => setForm({ ...form, condensed: e.target.checked })}
            />{' '}
            Condensed (leave out zero records)
          </label>
          <UnitsPicker />
          <Button
            type="submit"
            variant="primary"
            disabled={!valid || loading}
            busy={loading}
            data-testid="stats-load"
          >
            Show
          </Button>
        </form>
        {!valid && <p className="ui-muted small">The first day must be before the end day.</p>}
        <p className="ui-muted small">
          The machine clips the range to the days it keeps statistics for (its logging range).
        </p>
      </Panel>
      {error && (
        <Notice tone="bad" title="Statistics could not be read">
          {error}
        </Notice>
      )}
      {!data && loading && <EmptyState>Loading statistics…</EmptyState>}
      {data && <StatsBody session={session} />}
    </div>
  );
}
