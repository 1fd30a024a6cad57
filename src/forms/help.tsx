import { memo, useMemo, useState } from 'react';
import { useForm } from './context';
import { sanitizeHtml } from './sanitize';

/** Help texts: the controller's HTML descriptions, sanitized, behind a Help button. */

export function hasHelp(html: string): boolean {
  const t = html.trim();
  // Prunt sends "<p>None</p>" for some settings (an upstream quirk): no help to show.
  return t !== '' && t !== '<p>None</p>' && t !== 'None';
}

export function Description(props: { html: string }) {
  const { assetBase } = useForm();
  const [open, setOpen] = useState(false);
  if (!hasHelp(props.html)) return null;
  return (
    <div className="fm-desc">
      <button type="button" className="fm-help" aria-expanded={open} onClick={() => setOpen(!open)}>
        {open ? 'Hide help' : 'Help'}
      </button>
      {open && <SanitizedHtml html={props.html.trim()} base={assetBase} />}
    </div>
  );
}

export const SanitizedHtml = memo(function SanitizedHtml(props: { html: string; base: string }) {
  const clean = useMemo(() => sanitizeHtml(props.html, props.base), [props.html, props.base]);
  // Sanitized by DOMPurify just above: the only place controller HTML reaches the DOM.
  return <div className="fm-desc-body" dangerouslySetInnerHTML={{ __html: clean }} />;
});
