import { Field } from '../../ui';
import type { Shift } from './api';
import type { RangeChoice } from './range';

/** The range every section of the History page shows. */
export function RangePicker(props: {
  choice: RangeChoice;
  onChange: (c: RangeChoice) => void;
  shifts: readonly Shift[];
  today: string;
  error: string | null;
}) {
  const { choice, onChange, shifts, today } = props;
  return (
    <div className="history-range" data-testid="history-range">
      <Field label="Range">
        {(id) => (
          <select
            id={id}
            className="ui-input"
            value={choice.kind}
            data-testid="history-range-kind"
            onChange={(e) => {
              const k = e.target.value;
              if (k === 'shift') onChange({ kind: 'shift', date: today, shift: shifts[0]?.name ?? '' });
              else if (k === 'custom')
                onChange({ kind: 'custom', from: `${today}T00:00`, to: `${today}T23:59` });
              else if (k === 'today' || k === 'yesterday' || k === 'last7') onChange({ kind: k });
            }}
          >
            <option value="today">Today</option>
            <option value="yesterday">Yesterday</option>
            <option value="last7">Last 7 days</option>
            <option value="shift" disabled={shifts.length === 0}>
              A shift
            </option>
            <option value="custom">From … to …</option>
          </select>
        )}
      </Field>
      {choice.kind === 'shift' && (
        <>
          <Field label="Date">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="date"
                value={choice.date}
                onChange={(e) => onChange({ ...choice, date: e.target.value })}
              />
            )}
          </Field>
          <Field label="Shift">
            {(id) => (
              <select
                id={id}
                className="ui-input"
                value={choice.shift}
                onChange={(e) => onChange({ ...choice, shift: e.target.value })}
              >
                {shifts.map((s) => (
                  <option key={s.name} value={s.name}>
                    {s.name} ({s.start}–{s.end})
                  </option>
                ))}
              </select>
            )}
          </Field>
        </>
      )}
      {choice.kind === 'custom' && (
        <>
          <Field label="From">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="datetime-local"
                value={choice.from}
                onChange={(e) => onChange({ ...choice, from: e.target.value })}
              />
            )}
          </Field>
          <Field label="To">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="datetime-local"
                value={choice.to}
                onChange={(e) => onChange({ ...choice, to: e.target.value })}
              />
            )}
          </Field>
        </>
      )}
      {props.error && (
        <p className="history-range-error" role="alert">
          {props.error}
        </p>
      )}
    </div>
  );
}
