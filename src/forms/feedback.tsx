import { useStore } from 'zustand';
import { Badge, Button, Notice } from '../ui';
import { useForm } from './context';
import { defaultOf, valuesEqual } from './ir';
import { fmt, valueOf, type FormModel } from './model';

/**
 * What the form shows of its validation and edit state (the state itself is FormModel's): error
 * and unsaved-edit counts on sections and tabs, a field's local and controller errors, its
 * "Undo edit" and "Reset to default" actions, and the form-wide conflict and error notices.
 */

export function ErrorBadge(props: { id: string }) {
  const { model } = useForm();
  const n = useStore(model.store, (s) => s.errorCounts[props.id] ?? 0);
  if (!n) return null;
  return (
    <Badge tone="bad" plain title={`${n} error${n === 1 ? '' : 's'} inside`} testId={`errors-${props.id}`}>
      {n}
    </Badge>
  );
}

export function EditedBadge(props: { id: string }) {
  const { model } = useForm();
  const prefix = `${props.id}$`;
  const n = useStore(model.store, (s) => {
    let c = 0;
    for (const k in s.edits) if (k === props.id || k.startsWith(prefix)) c++;
    return c;
  });
  if (!n) return null;
  return (
    <Badge tone="info" plain title={`${n} unsaved edit${n === 1 ? '' : 's'}`}>
      ✎{n}
    </Badge>
  );
}

export function ServerErrors(props: { id: string }) {
  const { model } = useForm();
  const errs = useStore(model.store, (s) => s.serverErrors[props.id]);
  if (!errs?.length) return null;
  return (
    <div className="fm-error server" role="alert" data-testid={`server-error-${props.id}`}>
      {errs.map((e, i) => (
        <div key={i}>Controller: {e}</div>
      ))}
    </div>
  );
}

export function FieldErrors(props: { id: string }) {
  const { model } = useForm();
  const local = useStore(model.store, (s) => s.localErrors[props.id]);
  return (
    <>
      {local && (
        <div className="fm-error" role="alert" data-testid={`local-error-${props.id}`}>
          {local}
        </div>
      )}
      <ServerErrors id={props.id} />
    </>
  );
}

export function FieldActions(props: { id: string }) {
  const { model, readOnly } = useForm();
  const n = model.node(props.id);
  const edited = useStore(model.store, (s) => Boolean(s.edits[props.id]));
  const value = useStore(model.store, (s) => valueOf(s, model.schema, props.id));
  if (readOnly || !n) return null;
  const d = defaultOf(n);
  return (
    <span className="fm-actions">
      {edited && (
        <button
          type="button"
          className="fm-link"
          onClick={() => model.revert(props.id)}
          data-testid={`revert-${props.id}`}
        >
          Undo edit
        </button>
      )}
      {d !== undefined && !valuesEqual(d, value) && (
        <button
          type="button"
          className="fm-link"
          title={`Default: ${fmt(d)}`}
          onClick={() => model.resetToDefault(props.id)}
          data-testid={`default-${props.id}`}
        >
          Reset to default ({fmt(d)})
        </button>
      )}
    </span>
  );
}

export function Conflicts(props: { model: FormModel }) {
  const conflicts = useStore(props.model.store, (s) => s.conflicts);
  if (!conflicts.length) return null;
  return (
    <div className="ui-notice tone-warn" role="alert" data-testid="form-conflicts">
      <strong>
        {conflicts.length} unsaved edit{conflicts.length === 1 ? '' : 's'} conflict with the controller
      </strong>
      <ul>
        {conflicts.map((c) => (
          <li key={c.id}>
            <button type="button" className="fm-link" onClick={() => props.model.reveal(c.id)}>
              {c.label}
            </button>
            : {c.reason}
          </li>
        ))}
      </ul>
      <Button small onClick={() => props.model.dismissConflicts()}>
        Understood
      </Button>
    </div>
  );
}

export function Unplaced(props: { model: FormModel }) {
  const errs = useStore(props.model.store, (s) => s.unplacedErrors);
  if (!errs.length) return null;
  return (
    <Notice tone="bad" title="The controller reports">
      {errs.join(' · ')}
    </Notice>
  );
}
