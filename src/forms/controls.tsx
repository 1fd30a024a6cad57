import type { ReactNode } from 'react';
import { noLimitText, rangeText, type FormNode, type FormValue, type RatioValue } from './ir';
import type { FormModel } from './model';

/**
 * The widget of a field, by kind: a switch for a boolean, a select for a discrete choice, a
 * text input for numbers (kept as text until it parses) and strings, two inputs for a ratio;
 * and the hint shown below it. Layout, label and messages are FieldRow's.
 */

export interface FieldControlProps {
  model: FormModel;
  /** The id of the input the row's label points to. */
  inputId: string;
  value: FormValue | undefined;
  readOnly: boolean;
  hasError: boolean;
}

/** The control and hint of a value field; null for a node that is not one (groups, variants). */
export function fieldControl(
  n: FormNode,
  props: FieldControlProps,
): { control: ReactNode; hint: string | null } | null {
  const { model, inputId, value, readOnly, hasError } = props;
  let control: ReactNode;
  let hint: string | null = null;
  switch (n.kind) {
    case 'boolean':
      control = (
        <label className="fm-switch">
          <input
            id={inputId}
            type="checkbox"
            role="switch"
            checked={value === true}
            disabled={readOnly}
            onChange={(e) => model.set(n.id, e.target.checked)}
            data-testid={`field-${n.id}`}
          />
          <span>{value === true ? 'On' : 'Off'}</span>
        </label>
      );
      break;
    case 'discrete':
      control = (
        <select
          id={inputId}
          className="ui-input fm-control"
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          aria-invalid={hasError || undefined}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        >
          {typeof value !== 'string' && <option value="">—</option>}
          {n.options.map((o) => (
            <option key={o} value={o}>
              {o}
            </option>
          ))}
        </select>
      );
      break;
    case 'integer':
    case 'float':
      hint = `${n.kind === 'integer' ? 'whole number, ' : ''}${rangeText(n.min, n.max, n.unit)}`;
      control = (
        <span className="fm-num">
          <input
            id={inputId}
            className="ui-input fm-control"
            type="text"
            inputMode={n.kind === 'integer' ? 'numeric' : 'decimal'}
            autoComplete="off"
            value={numText(value)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, e.target.value)}
            data-testid={`field-${n.id}`}
          />
          {n.unit && <span className="fm-unit">{n.unit}</span>}
        </span>
      );
      break;
    case 'ratio': {
      const r: RatioValue = typeof value === 'object' ? value : { numerator: '', denominator: '' };
      hint = `numerator : denominator, ratio ${rangeText(n.min, n.max)}`;
      control = (
        <span className="fm-ratio">
          <input
            id={inputId}
            className="ui-input fm-control"
            type="text"
            inputMode="decimal"
            aria-label={`${n.label}: numerator`}
            value={numText(r.numerator)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, { numerator: e.target.value, denominator: r.denominator })}
            data-testid={`field-${n.id}-num`}
          />
          <span aria-hidden="true">:</span>
          <input
            className="ui-input fm-control"
            type="text"
            inputMode="decimal"
            aria-label={`${n.label}: denominator`}
            value={numText(r.denominator)}
            disabled={readOnly}
            aria-invalid={hasError || undefined}
            onChange={(e) => model.set(n.id, { numerator: r.numerator, denominator: e.target.value })}
            data-testid={`field-${n.id}-den`}
          />
        </span>
      );
      break;
    }
    case 'string':
      control = (
        <input
          id={inputId}
          className="ui-input fm-control"
          type="text"
          value={typeof value === 'string' ? value : ''}
          disabled={readOnly}
          aria-invalid={hasError || undefined}
          onChange={(e) => model.set(n.id, e.target.value)}
          data-testid={`field-${n.id}`}
        />
      );
      break;
    case 'unknown':
      control = <span className="ui-muted">unknown (raw {n.rawKind}): not editable here</span>;
      break;
    default:
      return null;
  }
  return { control, hint };
}

function numText(v: FormValue | undefined | number | string): string {
  if (v === undefined) return '';
  // Prunt's ±1E100 ("no limit") in words, not "1e+100"; the words are read back as the number.
  if (typeof v === 'number') return noLimitText(v) ?? String(v);
  if (typeof v === 'string') return v;
  return '';
}
