import { useEffect, useState } from 'react';
import { MANIFESTS } from '../../controllers';
import { Button, Field, KeyValues, Notice, Panel, formatBytes, formatDateTime, type Tone } from '../../ui';
import { request, settingsAnswerSchema, type HistoryInfo, type Shift } from './api';

interface Draft {
  shifts: Shift[];
  jobsDays: string;
  statesDays: string;
}

function draftOf(info: HistoryInfo): Draft {
  return {
    shifts: info.shifts.map((s) => ({ ...s })),
    jobsDays: String(info.retention.jobsDays),
    statesDays: String(info.retention.statesDays),
  };
}

/**
 * The daily statistics the console server imports (`counts` and `oldest` of the history's info),
 * named as the family that has them names them in its manifest.
 */
const STATISTICS_DAYS = MANIFESTS.find((m) => m.history?.statisticsDays)?.history?.statisticsDays;

/** Supervisors: the shifts, how long the history is kept, and how big its file is. */
export function HistorySettings(props: { info: HistoryInfo | null; onSaved: () => void }) {
  const { info } = props;
  const [draft, setDraft] = useState<Draft | null>(null);
  const [busy, setBusy] = useState(false);
  const [message, setMessage] = useState<{ tone: Tone; text: string } | null>(null);
  useEffect(() => {
    if (info) setDraft((d) => d ?? draftOf(info));
  }, [info]);
  if (!info || !draft) return null;

  const setShift = (i: number, patch: Partial<Shift>) =>
    setDraft({ ...draft, shifts: draft.shifts.map((s, j) => (j === i ? { ...s, ...patch } : s)) });

  const save = async () => {
    setBusy(true);
    setMessage(null);
    try {
      const r = await request(settingsAnswerSchema, '/api/settings', 'settings', {
        method: 'PUT',
        body: {
          shifts: draft.shifts.map((s) => ({ name: s.name.trim(), start: s.start, end: s.end })),
          retention: { jobsDays: Number(draft.jobsDays), statesDays: Number(draft.statesDays) },
        },
      });
      if (!r.ok) setMessage({ tone: 'bad', text: `Not saved: ${r.error}` });
      else {
        setDraft({
          shifts: r.data.shifts,
          jobsDays: String(r.data.retention.jobsDays),
          statesDays: String(r.data.retention.statesDays),
        });
        setMessage({ tone: 'ok', text: 'Saved. Older records are pruned now.' });
        props.onSaved();
      }
    } finally {
      setBusy(false);
    }
  };

  return (
    <Panel title="Shifts and retention" testId="history-settings">
      <KeyValues
        testId="history-info"
        items={[
          ['History file', formatBytes(info.sizeBytes)],
          ['Jobs kept', `${info.counts.jobs} (oldest ${formatDateTime(info.oldest.jobAt)})`],
          ['State changes kept', `${info.counts.states} (oldest ${formatDateTime(info.oldest.stateAt)})`],
          ...(STATISTICS_DAYS
            ? [
                [
                  STATISTICS_DAYS,
                  `${info.counts.touchcutDays}${info.oldest.touchcutDay ? ` (oldest ${info.oldest.touchcutDay})` : ''}`,
                ] satisfies [string, string],
              ]
            : []),
        ]}
      />
      <form
        className="history-settings-form"
        onSubmit={(e) => {
          e.preventDefault();
          void save();
        }}
      >
        <fieldset>
          <legend>Shifts (the server’s local time; an end before the start is the next day)</legend>
          {draft.shifts.map((s, i) => (
            <div className="ui-row history-shift-edit" key={i} data-testid="history-shift-row">
              <Field label="Name">
                {(id) => (
                  <input
                    id={id}
                    className="ui-input"
                    value={s.name}
                    maxLength={40}
                    onChange={(e) => setShift(i, { name: e.target.value })}
                  />
                )}
              </Field>
              <TimeField label="Start" value={s.start} onChange={(v) => setShift(i, { start: v })} />
              <TimeField label="End" value={s.end} onChange={(v) => setShift(i, { end: v })} />
              <Button
                onClick={() => setDraft({ ...draft, shifts: draft.shifts.filter((_, j) => j !== i) })}
                aria-label={`Remove shift ${s.name}`}
              >
                Remove
              </Button>
            </div>
          ))}
          {draft.shifts.length < 12 && (
            <Button
              onClick={() =>
                setDraft({ ...draft, shifts: [...draft.shifts, { name: '', start: '06:00', end: '14:00' }] })
              }
            >
              Add a shift
            </Button>
          )}
        </fieldset>
        <fieldset>
          <legend>Keep the history</legend>
          <div className="ui-row">
            <DaysField
              label="Jobs, days"
              value={draft.jobsDays}
              onChange={(v) => setDraft({ ...draft, jobsDays: v })}
            />
            <DaysField
              label="State changes, days"
              value={draft.statesDays}
              onChange={(v) => setDraft({ ...draft, statesDays: v })}
            />
          </div>
        </fieldset>
        <div className="ui-row">
          <Button type="submit" variant="primary" disabled={busy} data-testid="history-settings-save">
            Save
          </Button>
          <Button disabled={busy} onClick={() => setDraft(draftOf(info))}>
            Undo changes
          </Button>
        </div>
      </form>
      {message && (
        <Notice tone={message.tone}>
          <span data-testid="history-settings-message">{message.text}</span>
        </Notice>
      )}
    </Panel>
  );
}

/** A shift's start or end (HH:MM, the server's local time). */
function TimeField(props: { label: string; value: string; onChange: (v: string) => void }) {
  return (
    <Field label={props.label}>
      {(id) => (
        <input
          id={id}
          className="ui-input"
          type="time"
          value={props.value}
          onChange={(e) => props.onChange(e.target.value)}
        />
      )}
    </Field>
  );
}

/** How many days a kind of record is kept (1 to 3650). */
function DaysField(props: { label: string; value: string; onChange: (v: string) => void }) {
  return (
    <Field label={props.label} hint="1 to 3650">
      {(id) => (
        <input
          id={id}
          className="ui-input history-days"
          type="number"
          min={1}
          max={3650}
          step={1}
          value={props.value}
          onChange={(e) => props.onChange(e.target.value)}
        />
      )}
    </Field>
  );
}
