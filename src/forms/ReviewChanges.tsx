import { useMemo, type ReactNode } from 'react';
import { useStore } from 'zustand';
import { Dialog, Notice } from '../ui';
import { fmt, type FormModel } from './model';

/** "Review changes": every changed value, old → new, before anything is sent. */
export function ReviewChanges(props: {
  model: FormModel;
  onCancel: () => void;
  actions: ReactNode;
  note?: ReactNode;
}) {
  const edits = useStore(props.model.store, (s) => s.edits);
  const changes = useMemo(() => props.model.changes(), [props.model, edits]); // eslint-disable-line react-hooks/exhaustive-deps
  const errors = useStore(props.model.store, (s) => Object.keys(s.localErrors).length);
  return (
    <Dialog title="Review changes" onCancel={props.onCancel} actions={props.actions} testId="review-dialog">
      {changes.length === 0 ? (
        <p>No changes.</p>
      ) : (
        <table className="ui-table fm-review" data-testid="review-table">
          <thead>
            <tr>
              <th scope="col">Setting</th>
              <th scope="col">Now</th>
              <th scope="col">New</th>
            </tr>
          </thead>
          <tbody>
            {changes.map((c) => (
              <tr key={c.id}>
                <td>{c.label}</td>
                <td className="mono">{fmt(c.from)}</td>
                <td className="mono">
                  <strong>{fmt(c.to)}</strong>
                  {c.node.kind !== 'ratio' && c.node.kind !== 'boolean' && 'unit' in c.node && c.node.unit
                    ? ` ${c.node.unit}`
                    : ''}
                </td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
      {errors > 0 && (
        <Notice tone="bad">
          {errors} value{errors === 1 ? ' is' : 's are'} invalid: fix {errors === 1 ? 'it' : 'them'} before
          saving.
        </Notice>
      )}
      {props.note}
    </Dialog>
  );
}
