import { memo, useState } from 'react';
import { useStore } from 'zustand';
import { Badge } from '../ui';
import { useForm } from './context';
import { fieldControl } from './controls';
import { FieldActions, FieldErrors } from './feedback';
import { hasHelp, SanitizedHtml } from './help';
import { valueOf } from './model';

/**
 * One value field: label with its badges and help, the control (controls.tsx) with its undo and
 * reset actions, the hint and the field's errors. It selects only its own slice of the store, so
 * typing in one field re-renders that field alone.
 */
export const FieldRow = memo(function FieldRow(props: { id: string; compact?: boolean }) {
  const { model, readOnly, assetBase } = useForm();
  const [help, setHelp] = useState(false);
  const n = model.node(props.id);
  const value = useStore(model.store, (s) => valueOf(s, model.schema, props.id));
  const edited = useStore(model.store, (s) => Boolean(s.edits[props.id]));
  const hasError = useStore(model.store, (s) => Boolean(s.localErrors[props.id] || s.serverErrors[props.id]));
  if (!n) return null;
  const inputId = `fm-${props.id}`;
  const field = fieldControl(n, { model, inputId, value, readOnly, hasError });
  if (!field) return null;
  const { control, hint } = field;
  return (
    <div
      className={`fm-field${edited ? ' edited' : ''}${hasError ? ' invalid' : ''}`}
      data-testid={`row-${n.id}`}
    >
      <div className="fm-label">
        <label htmlFor={inputId}>{n.label}</label>
        {n.experimental && (
          <Badge tone="warn" plain>
            experimental
          </Badge>
        )}
        {edited && (
          <Badge tone="info" plain>
            edited
          </Badge>
        )}
        {!props.compact && hasHelp(n.description) && (
          <button type="button" className="fm-help" aria-expanded={help} onClick={() => setHelp(!help)}>
            {help ? 'Hide help' : 'Help'}
          </button>
        )}
      </div>
      <div className="fm-row">
        {control}
        <FieldActions id={n.id} />
      </div>
      {hint && <div className="fm-hint ui-muted">{hint}</div>}
      <FieldErrors id={n.id} />
      {help && <SanitizedHtml html={n.description.trim()} base={assetBase} />}
    </div>
  );
});
